//! `--config FILE.toml` for the services and `evgate run`: a file whose keys are the command's
//! flags (kebab-case, without the dashes) supplies values that the command line overrides, so a
//! value comes from the flag, else the file, else the flag's default.
//!
//! The file's entries become flags placed before the user's own, except those the command line
//! gives itself, so one parser serves both and every flag has a key by construction.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use clap::{ArgAction, CommandFactory, FromArgMatches};

/// The flag that names the file; every command that reads one declares it.
pub const CONFIG_FLAG: &str = "config";

/// Why a command line with `--config` could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileError {
    #[error("cannot read the config file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("config file {path} is not valid TOML: {source}")]
    Syntax {
        path: PathBuf,
        source: Box<toml::de::Error>,
    },
    #[error("config file {path}: unknown key `{key}`; accepted keys: {accepted}")]
    UnknownKey {
        path: PathBuf,
        key: String,
        accepted: String,
    },
    #[error("config file {path}: key `{key}` = {value} must be {expected}")]
    BadValue {
        path: PathBuf,
        key: String,
        value: String,
        expected: &'static str,
    },
    #[error("--config needs a file name")]
    MissingPath,
    #[error(transparent)]
    CommandLine(#[from] clap::Error),
}

/// Parses `P` from the process's arguments with `--config` applied (to the flags of
/// `subcommand`, see [`try_parse_with_config_file`]); prints clap's message or the file's error
/// and exits on failure, as `Parser::parse` does.
pub fn parse_with_config_file<P: CommandFactory + FromArgMatches>(subcommand: &[&str]) -> P {
    match try_parse_with_config_file::<P>(std::env::args_os(), subcommand) {
        Ok(parsed) => parsed,
        Err(ConfigFileError::CommandLine(error)) => error.exit(),
        Err(error) => {
            eprintln!("error: {error}");
            std::process::exit(2);
        }
    }
}

/// Parses `P` from `args` (program name first) with `--config` applied. `subcommand` names the
/// path of subcommands whose flags the file holds (`["run"]` for `evgate run`); the file's flags
/// go right after it, and only when the command line uses it.
pub fn try_parse_with_config_file<P: CommandFactory + FromArgMatches>(
    args: impl IntoIterator<Item = impl Into<OsString>>,
    subcommand: &[&str],
) -> Result<P, ConfigFileError> {
    let args: Vec<OsString> = args.into_iter().map(Into::into).collect();
    let command = P::command();
    let uses_subcommand = args.iter().skip(1).take(subcommand.len()).eq(subcommand
        .iter()
        .map(OsString::from)
        .collect::<Vec<_>>()
        .iter());
    let mut args = args;
    let at = 1 + subcommand.len();
    if uses_subcommand {
        if let Some(path) = config_path(&args[at..])? {
            let target = subcommand.iter().fold(&command, |command, name| {
                command
                    .find_subcommand(name)
                    .expect("the caller names a subcommand of the command")
            });
            let from_file = flags_from_file(target, &path, &args[at..])?;
            args.splice(at..at, from_file);
        }
    }
    let matches = command.try_get_matches_from(args)?;
    Ok(P::from_arg_matches(&matches)?)
}

/// The value of the last `--config PATH` or `--config=PATH` before a `--`.
fn config_path(args: &[OsString]) -> Result<Option<PathBuf>, ConfigFileError> {
    let flag = format!("--{CONFIG_FLAG}");
    let with_value = format!("--{CONFIG_FLAG}=");
    let mut path = None;
    let mut rest = args.iter();
    while let Some(arg) = rest.next() {
        let text = arg.to_string_lossy();
        if text == "--" {
            break;
        } else if text == flag {
            path = Some(PathBuf::from(
                rest.next().ok_or(ConfigFileError::MissingPath)?,
            ));
        } else if let Some(value) = text.strip_prefix(&with_value) {
            path = Some(PathBuf::from(value));
        }
    }
    Ok(path)
}

/// The file's entries as flags of `command`, less those `given` on the command line.
fn flags_from_file(
    command: &clap::Command,
    path: &Path,
    given: &[OsString],
) -> Result<Vec<OsString>, ConfigFileError> {
    let on_command_line = |key: &str| {
        let (flag, with_value) = (format!("--{key}"), format!("--{key}="));
        given
            .iter()
            .map(|arg| arg.to_string_lossy())
            .take_while(|arg| arg != "--")
            .any(|arg| arg == flag || arg.starts_with(&with_value))
    };
    let text = std::fs::read_to_string(path).map_err(|source| ConfigFileError::Read {
        path: path.to_owned(),
        source,
    })?;
    let table: toml::Table = text.parse().map_err(|source| ConfigFileError::Syntax {
        path: path.to_owned(),
        source: Box::new(source),
    })?;
    let keyed: Vec<&clap::Arg> = command
        .get_arguments()
        .filter(|arg| arg.get_long().is_some_and(|long| long != CONFIG_FLAG))
        .filter(|arg| !matches!(arg.get_action(), ArgAction::Help | ArgAction::Version))
        .collect();
    let mut flags = Vec::new();
    for (key, value) in &table {
        let Some(arg) = keyed
            .iter()
            .find(|arg| arg.get_long() == Some(key.as_str()))
        else {
            let accepted: Vec<&str> = keyed.iter().filter_map(|arg| arg.get_long()).collect();
            return Err(ConfigFileError::UnknownKey {
                path: path.to_owned(),
                key: key.clone(),
                accepted: accepted.join(", "),
            });
        };
        let bad_value = |expected| ConfigFileError::BadValue {
            path: path.to_owned(),
            key: key.clone(),
            value: value.to_string(),
            expected,
        };
        if on_command_line(key) {
            continue;
        }
        let flag = OsString::from(format!("--{key}"));
        if !arg.get_action().takes_values() {
            match value {
                toml::Value::Boolean(true) => flags.push(flag),
                toml::Value::Boolean(false) => {}
                _ => return Err(bad_value("true or false")),
            }
            continue;
        }
        let values = match value {
            toml::Value::Array(items) => items
                .iter()
                .map(scalar)
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| bad_value("a string, a number or an array of them"))?,
            other => vec![scalar(other).ok_or_else(|| bad_value("a string or a number"))?],
        };
        for value in values {
            flags.push(flag.clone());
            flags.push(OsString::from(value));
        }
    }
    Ok(flags)
}

/// Writes `config` (a command's settings, serialised with its flags' kebab-case names) as a
/// file that `--config` reads back; settings left unset (None) are left out.
pub fn write_config_file(
    config: &impl serde::Serialize,
    path: &Path,
) -> Result<(), ConfigFileWriteError> {
    let text = toml::to_string(config).map_err(|source| ConfigFileWriteError::Serialise {
        path: path.to_owned(),
        source,
    })?;
    std::fs::write(path, text).map_err(|source| ConfigFileWriteError::Write {
        path: path.to_owned(),
        source,
    })
}

/// Why a config file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileWriteError {
    #[error("cannot express the settings for {path} in TOML: {source}")]
    Serialise {
        path: PathBuf,
        source: toml::ser::Error,
    },
    #[error("cannot write the config file {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Serialises a sensor size as `--sensor` takes it (`WIDTHxHEIGHT`).
pub fn sensor_as_flag<S: serde::Serializer>(
    sensor: &Option<evgate_core::SensorSize>,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    match sensor {
        Some(sensor) => serializer.serialize_str(&sensor.to_string()),
        None => serializer.serialize_none(),
    }
}

/// A TOML scalar as it would be typed on the command line.
fn scalar(value: &toml::Value) -> Option<String> {
    match value {
        toml::Value::String(text) => Some(text.clone()),
        toml::Value::Integer(number) => Some(number.to_string()),
        toml::Value::Float(number) => Some(number.to_string()),
        toml::Value::Boolean(flag) => Some(flag.to_string()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[derive(clap::Parser, Debug, serde::Serialize)]
    #[serde(rename_all = "kebab-case")]
    struct Service {
        /// File of defaults.
        #[arg(long)]
        #[serde(skip)]
        config: Option<PathBuf>,
        #[arg(long, default_value = "evgate")]
        domain: String,
        #[arg(long, default_value_t = 1.0)]
        batch_ms: f64,
        #[arg(long)]
        fast: bool,
        #[arg(long, value_delimiter = ',')]
        horizons_ms: Vec<f32>,
    }

    #[derive(clap::Parser, Debug)]
    enum Tool {
        Run(Service),
        Info { file: PathBuf },
    }

    fn file(text: &str) -> tempfile::NamedTempFile {
        let mut file = tempfile::NamedTempFile::with_suffix(".toml").unwrap();
        file.write_all(text.as_bytes()).unwrap();
        file
    }

    fn parse(args: &[&str]) -> Result<Service, ConfigFileError> {
        let mut all = vec!["service"];
        all.extend_from_slice(args);
        try_parse_with_config_file::<Service>(all, &[])
    }

    #[test]
    fn a_flag_beats_the_file_which_beats_the_default() {
        let config =
            file("domain = \"lab\"\nbatch-ms = 2.5\nfast = true\nhorizons-ms = [10, 20]\n");
        let path = config.path().to_str().unwrap();
        let from_file = parse(&["--config", path]).unwrap();
        assert_eq!(from_file.domain, "lab");
        assert_eq!(from_file.batch_ms, 2.5);
        assert!(from_file.fast);
        assert_eq!(from_file.horizons_ms, [10.0, 20.0]);

        let flags = parse(&[
            "--batch-ms",
            "4",
            &format!("--config={path}"),
            "--horizons-ms",
            "5",
        ])
        .unwrap();
        assert_eq!(flags.domain, "lab");
        assert_eq!(flags.batch_ms, 4.0);
        assert_eq!(flags.horizons_ms, [5.0]);

        let defaults = parse(&[]).unwrap();
        assert_eq!(defaults.domain, "evgate");
        assert_eq!(defaults.batch_ms, 1.0);
        assert!(!defaults.fast);
    }

    #[test]
    fn a_written_config_reads_back_as_the_same_settings() {
        let written = Service {
            config: None,
            domain: "lab".to_owned(),
            batch_ms: 2.5,
            fast: true,
            horizons_ms: vec![10.0, 20.0],
        };
        let directory = tempfile::tempdir().unwrap();
        let path = directory.path().join("service.toml");
        write_config_file(&written, &path).unwrap();
        let read = parse(&["--config", path.to_str().unwrap()]).unwrap();
        assert_eq!(read.domain, written.domain);
        assert_eq!(read.batch_ms, written.batch_ms);
        assert_eq!(read.fast, written.fast);
        assert_eq!(read.horizons_ms, written.horizons_ms);
    }

    #[test]
    fn an_unknown_key_names_itself_and_the_accepted_ones() {
        let config = file("domian = \"lab\"\n");
        let message = parse(&["--config", config.path().to_str().unwrap()])
            .unwrap_err()
            .to_string();
        assert!(
            message.contains(&config.path().display().to_string()),
            "{message}"
        );
        assert!(
            message.contains("unknown key `domian`")
                && message.contains("accepted keys: domain, batch-ms, fast, horizons-ms"),
            "{message}"
        );
    }

    #[test]
    fn a_value_of_the_wrong_kind_names_the_key_and_value() {
        let config = file("fast = \"yes\"\n");
        let message = parse(&["--config", config.path().to_str().unwrap()])
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("key `fast` = \"yes\" must be true or false"),
            "{message}"
        );
        let config = file("[domain]\nname = 1\n");
        let message = parse(&["--config", config.path().to_str().unwrap()])
            .unwrap_err()
            .to_string();
        assert!(message.contains("key `domain`"), "{message}");
    }

    #[test]
    fn a_value_clap_rejects_is_clap_s_error() {
        let config = file("batch-ms = \"fast\"\n");
        let error = parse(&["--config", config.path().to_str().unwrap()]).unwrap_err();
        assert!(matches!(error, ConfigFileError::CommandLine(_)), "{error}");
        assert!(error.to_string().contains("--batch-ms"), "{error}");
    }

    #[test]
    fn a_missing_or_malformed_file_is_named() {
        let message = parse(&["--config", "/nonexistent/evgate.toml"])
            .unwrap_err()
            .to_string();
        assert!(message.contains("/nonexistent/evgate.toml"), "{message}");
        let config = file("domain = \n");
        let message = parse(&["--config", config.path().to_str().unwrap()])
            .unwrap_err()
            .to_string();
        assert!(message.contains("not valid TOML"), "{message}");
        assert!(matches!(
            parse(&["--config"]).unwrap_err(),
            ConfigFileError::MissingPath
        ));
    }

    #[test]
    fn a_subcommand_takes_its_own_flags_from_the_file() {
        let config = file("domain = \"lab\"\n");
        let path = config.path().to_str().unwrap();
        let Tool::Run(run) =
            try_parse_with_config_file::<Tool>(["tool", "run", "--config", path], &["run"])
                .unwrap()
        else {
            panic!("parsed another subcommand");
        };
        assert_eq!(run.domain, "lab");
        let Tool::Info { file } =
            try_parse_with_config_file::<Tool>(["tool", "info", "x.raw"], &["run"]).unwrap()
        else {
            panic!("parsed another subcommand");
        };
        assert_eq!(file, PathBuf::from("x.raw"));
    }
}

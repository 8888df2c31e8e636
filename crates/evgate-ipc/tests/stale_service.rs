//! A process killed while it creates a service leaves that service's static config locked
//! (writable) forever; opening the stream must recover unless a live node may still be creating it.

use std::fs::Permissions;
use std::os::unix::fs::PermissionsExt;
use std::path::PathBuf;

use evgate_ipc::stale_service::remove_unfinished_dynamic_configs;
use evgate_ipc::{
    create_node, evgate_config, LatestPublisher, LatestSubscriber, PipelineNames, PipelineStats,
    Stream,
};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};

/// Mode of a static config whose creator has not finished (iceoryx2 makes it read-only when done).
const LOCKED: u32 = 0o600;
const FINISHED: u32 = 0o400;

fn unique_names(test: &str) -> PipelineNames {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    PipelineNames::new(&format!("ipc-{test}-{}-{nanos}", std::process::id()), "cam").unwrap()
}

/// Finds the static config of the publish-subscribe service `service` by its content, in the
/// directory iceoryx2 reports, so the test does not share the path computation it checks.
fn publish_subscribe_static_config(service: &str) -> PathBuf {
    let directory = evgate_config().unwrap().global.service_dir().to_string();
    let needle = format!("service_name = \"{service}\"");
    std::fs::read_dir(&directory)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .find(|path| {
            std::fs::read_to_string(path).is_ok_and(|content| {
                content.contains(&needle)
                    && content.contains("[messaging_pattern.PublishSubscribe]")
            })
        })
        .unwrap_or_else(|| panic!("no static config of {service} in {directory}"))
}

fn set_mode(path: &PathBuf, mode: u32) {
    std::fs::set_permissions(path, Permissions::from_mode(mode)).unwrap();
}

#[test]
fn a_stream_whose_creator_died_while_creating_it_is_created_afresh() {
    let names = unique_names("stale-dead");
    let service = names.service(Stream::Stats).unwrap();

    // What a creator killed after writing the static config but before finishing it leaves:
    // the same file, still writable, and no node that claims the service.
    let (path, content) = {
        let creator = create_node("ipc-test-stale-creator").unwrap();
        let publisher =
            LatestPublisher::<PipelineStats>::open(&creator, &names, Stream::Stats).unwrap();
        let path = publish_subscribe_static_config(service.as_str());
        let content = std::fs::read(&path).unwrap();
        drop(publisher);
        (path, content)
    };
    assert!(!path.exists(), "the last owner removes the service");
    std::fs::write(&path, &content).unwrap();
    set_mode(&path, LOCKED);

    let node = create_node("ipc-test-stale-reader").unwrap();
    let raw = node
        .service_builder(&service)
        .publish_subscribe::<PipelineStats>()
        .open_or_create();
    assert!(
        matches!(
            raw,
            Err(
                PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    PublishSubscribeOpenError::HangsInCreation
                )
            )
        ),
        "iceoryx2 alone must find the service stuck in creation, got {:?}",
        raw.err()
    );

    let subscriber = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();
    let publisher = LatestPublisher::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();
    let stats = PipelineStats {
        input_events: 42,
        ..PipelineStats::default()
    };
    publisher.publish(stats).unwrap();
    assert_eq!(
        subscriber.latest().unwrap().map(|s| s.input_events),
        Some(42)
    );
}

#[test]
fn a_stream_a_live_node_may_still_be_creating_is_left_alone() {
    let names = unique_names("stale-live");
    let creator = create_node("ipc-test-live-creator").unwrap();
    let publisher =
        LatestPublisher::<PipelineStats>::open(&creator, &names, Stream::Stats).unwrap();
    let path = publish_subscribe_static_config(names.service(Stream::Stats).unwrap().as_str());
    // Looks like a creation in progress by a node that is alive.
    set_mode(&path, LOCKED);

    let node = create_node("ipc-test-live-reader").unwrap();
    let outcome = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats);
    let still_there = path.exists();
    set_mode(&path, FINISHED);
    let error = outcome
        .err()
        .expect("opening a service in creation must fail");
    assert!(
        error.to_string().contains("HangsInCreation"),
        "unexpected error: {error}"
    );
    assert!(
        still_there,
        "the static config of a live creator was removed"
    );
    drop(publisher);
}

/// A shared-memory object named like an iceoryx2 dynamic config of this test.
fn dynamic_config_path(test: &str) -> PathBuf {
    let global = &evgate_config().unwrap().global;
    PathBuf::from("/dev/shm").join(format!(
        "{}evgate-test-{test}-{}{}",
        global.prefix,
        std::process::id(),
        global.service.dynamic_config_storage_suffix
    ))
}

#[test]
fn an_empty_dynamic_config_nobody_may_read_is_removed_once_the_creation_timeout_passed() {
    // What a creator killed between creating its dynamic config and sizing it leaves; iceoryx2
    // 0.10 would wait for it to grow forever when cleaning up that creator's node.
    let abandoned = dynamic_config_path("abandoned");
    std::fs::write(&abandoned, b"").unwrap();
    set_mode(&abandoned, 0o200);
    let finished = dynamic_config_path("finished");
    std::fs::write(&finished, b"").unwrap();
    set_mode(&finished, 0o600);

    // Node creations of the other tests of this binary may remove it first.
    remove_unfinished_dynamic_configs(evgate_config().unwrap()).unwrap();
    let finished_kept = finished.exists();
    std::fs::remove_file(&finished).unwrap();
    assert!(
        !abandoned.exists(),
        "{} is still there",
        abandoned.display()
    );
    assert!(finished_kept, "a readable dynamic config was removed");
}

/// Issue 15: the scan of `/dev/shm` removed any unfinished iceoryx2 dynamic config, other
/// users' included. Only root can give a file away, so elsewhere this test has nothing to try.
#[test]
fn another_users_unfinished_dynamic_config_is_left_alone() {
    // SAFETY: geteuid has no preconditions and cannot fail.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipped: only root can create a file owned by another user");
        return;
    }
    let foreign = dynamic_config_path("foreign");
    std::fs::write(&foreign, b"").unwrap();
    set_mode(&foreign, 0o200);
    std::os::unix::fs::chown(&foreign, Some(4242), None).unwrap();
    // Old enough that its creation timeout has passed, as for an abandoned one of ours.
    remove_unfinished_dynamic_configs(evgate_config().unwrap()).unwrap();
    let kept = foreign.exists();
    std::fs::remove_file(&foreign).unwrap();
    assert!(kept, "another user's dynamic config was removed");
}

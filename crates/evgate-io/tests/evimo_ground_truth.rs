//! EVIMO ground truth in its three layouts, built here the way EVIMO's tools write them:
//! metadata as a pickled object array (NumPy's `np.savez(meta=dict)`) or a Python literal,
//! masks as object id × 1000, depth in millimetres.

use std::fs::File;
use std::path::Path;

use evgate_core::{Event, SensorSize};
use evgate_io::npy::{DType, NpyArray};
use evgate_io::npz::{NpzCompression, NpzWriter};
use evgate_io::{read_all, EvimoLayout, EvimoRecording, GtFrame};

const WIDTH: usize = 12;
const HEIGHT: usize = 8;
/// Frame times in seconds; frame 1 has no ground truth (no `gt_frame`, no mask member).
const FRAME_TS: [f64; 4] = [0.031794, 0.056794, 0.081794, 0.106794];
const GT_FRAMES: [usize; 3] = [0, 2, 3];

/// A Python value to pickle.
enum Py {
    Str(&'static str),
    Float(f64),
    Int(i32),
    List(Vec<Py>),
    Dict(Vec<(&'static str, Py)>),
}

fn pickle_value(value: &Py, out: &mut Vec<u8>) {
    let text = |out: &mut Vec<u8>, s: &str| {
        out.push(0x8c);
        out.push(s.len() as u8);
        out.extend_from_slice(s.as_bytes());
    };
    match value {
        Py::Str(s) => text(out, s),
        Py::Float(f) => {
            out.push(b'G');
            out.extend_from_slice(&f.to_be_bytes());
        }
        Py::Int(i) => {
            out.push(b'J');
            out.extend_from_slice(&i.to_le_bytes());
        }
        Py::List(items) => {
            out.extend_from_slice(&[b']', 0x94, b'(']);
            for item in items {
                pickle_value(item, out);
            }
            out.push(b'e');
        }
        Py::Dict(items) => {
            out.extend_from_slice(&[b'}', 0x94, b'(']);
            for (key, item) in items {
                text(out, key);
                pickle_value(item, out);
            }
            out.push(b'u');
        }
    }
}

/// The bytes NumPy writes for `np.array(dict, dtype=object)`: a pickle of
/// `_reconstruct(ndarray, (0,), b'b')` built with the state `(1, (), dtype, False, [dict])`.
fn pickled_object_array(meta: &Py) -> Vec<u8> {
    let mut out = vec![0x80, 4, b'c'];
    out.extend_from_slice(b"numpy._core.multiarray\n_reconstruct\n");
    out.push(b'c');
    out.extend_from_slice(b"numpy\nndarray\n");
    out.extend_from_slice(&[b'K', 0, 0x85, b'C', 1, b'b', 0x87, b'R']);
    out.extend_from_slice(&[b'(', b'K', 1, b')', b'c']);
    out.extend_from_slice(b"numpy\ndtype\n");
    out.extend_from_slice(&[0x8c, 2, b'O', b'8', 0x89, 0x88, 0x87, b'R', 0x89, b']']);
    pickle_value(meta, &mut out);
    out.extend_from_slice(b"atb.");
    out
}

fn meta(with_resolution: bool) -> Py {
    let frames = FRAME_TS
        .iter()
        .enumerate()
        .map(|(i, &ts)| {
            let mut entry = vec![("id", Py::Int(i as i32)), ("ts", Py::Float(ts))];
            if GT_FRAMES.contains(&i) {
                entry.push((
                    "gt_frame",
                    Py::Str(
                        [
                            "depth_mask_0.png",
                            "",
                            "depth_mask_2.png",
                            "depth_mask_3.png",
                        ][i],
                    ),
                ));
            }
            Py::Dict(entry)
        })
        .collect();
    let mut camera = vec![("fx", Py::Float(200.0))];
    if with_resolution {
        camera.push(("res_x", Py::Int(WIDTH as i32)));
        camera.push(("res_y", Py::Int(HEIGHT as i32)));
    }
    Py::Dict(vec![
        ("meta", Py::Dict(camera)),
        ("frames", Py::List(frames)),
        ("full_trajectory", Py::List(vec![])),
    ])
}

fn object_array(meta: &Py) -> NpyArray {
    NpyArray {
        dtype: DType::Object,
        shape: vec![],
        data: pickled_object_array(meta),
    }
}

/// Raw mask of frame `i`: object `i + 1` (value × 1000) on a block, object 22 on a column.
fn raw_mask(i: usize) -> Vec<u16> {
    (0..WIDTH * HEIGHT)
        .map(|p| {
            let (x, y) = (p % WIDTH, p / WIDTH);
            if x == 11 {
                22_000
            } else if (i..i + 3).contains(&x) && y < 4 {
                (i as u16 + 1) * 1000
            } else {
                0
            }
        })
        .collect()
}

fn raw_depth(i: usize) -> Vec<u16> {
    (0..WIDTH * HEIGHT)
        .map(|p| (1000 + 10 * i + p) as u16)
        .collect()
}

fn events() -> Vec<(f64, u16, u16, u8)> {
    (0..500)
        .map(|i| {
            (
                0.03 + i as f64 * 1e-4,
                (i % WIDTH) as u16,
                (i % HEIGHT) as u16,
                (i % 2) as u8,
            )
        })
        .collect()
}

fn check_frames(recording: &EvimoRecording, with_depth: bool) {
    assert_eq!(
        recording.sensor_size(),
        SensorSize::new(WIDTH as u16, HEIGHT as u16)
    );
    let frames: Vec<GtFrame> = recording.frames().unwrap().map(Result::unwrap).collect();
    let indices: Vec<usize> = frames.iter().map(|f| f.index).collect();
    assert_eq!(indices, GT_FRAMES);
    for frame in &frames {
        let i = frame.index;
        assert_eq!(frame.t_us, (FRAME_TS[i] * 1e6).round() as i64);
        let expected: Vec<u16> = raw_mask(i).iter().map(|v| v / 1000).collect();
        assert_eq!(frame.mask, expected, "frame {i}");
        assert_eq!(frame.mask[11], 22);
        match (&frame.depth, with_depth) {
            (Some(depth), true) => {
                assert_eq!(depth.len(), WIDTH * HEIGHT);
                assert!((depth[5] - (1000 + 10 * i + 5) as f32 * 1e-3).abs() < 1e-6);
            }
            (None, false) => {}
            (depth, _) => panic!("frame {i}: depth {depth:?}, expected present = {with_depth}"),
        }
    }
    let decoded = read_all(recording.events().unwrap().as_mut()).unwrap();
    let expected: Vec<Event> = events()
        .iter()
        .map(|&(t, x, y, p)| Event::new((t * 1e6).round() as i64, x, y, p == 1))
        .collect();
    assert_eq!(decoded, expected);
}

fn write_npy(path: &Path, array: &NpyArray) {
    array.write(&mut File::create(path).unwrap()).unwrap();
}

fn write_evimo2_folder(folder: &Path, with_depth: bool) {
    let mut info =
        NpzWriter::create(folder.join("dataset_info.npz"), NpzCompression::Stored).unwrap();
    info.add("discretization", &[], &[0.01f64]).unwrap();
    info.add_array("meta", &object_array(&meta(true))).unwrap();
    info.finish().unwrap();
    let mut masks =
        NpzWriter::create(folder.join("dataset_mask.npz"), NpzCompression::Deflated).unwrap();
    let mut depths =
        NpzWriter::create(folder.join("dataset_depth.npz"), NpzCompression::Deflated).unwrap();
    for i in GT_FRAMES {
        masks
            .add(&format!("mask_{i:010}"), &[HEIGHT, WIDTH], &raw_mask(i))
            .unwrap();
        depths
            .add(&format!("depth_{i:010}"), &[HEIGHT, WIDTH], &raw_depth(i))
            .unwrap();
    }
    masks.finish().unwrap();
    depths.finish().unwrap();
    if !with_depth {
        std::fs::remove_file(folder.join("dataset_depth.npz")).unwrap();
    }
    let ev = events();
    let t: Vec<f64> = ev.iter().map(|e| e.0).collect();
    let xy: Vec<u16> = ev.iter().flat_map(|e| [e.1, e.2]).collect();
    let p: Vec<u8> = ev.iter().map(|e| e.3).collect();
    write_npy(
        &folder.join("dataset_events_t.npy"),
        &NpyArray::from_slice(&[ev.len()], &t),
    );
    write_npy(
        &folder.join("dataset_events_xy.npy"),
        &NpyArray::from_slice(&[ev.len(), 2], &xy),
    );
    write_npy(
        &folder.join("dataset_events_p.npy"),
        &NpyArray::from_slice(&[ev.len()], &p),
    );
}

#[test]
fn evimo2_folder_gives_times_object_ids_and_depth() {
    for with_depth in [true, false] {
        let dir = tempfile::tempdir().unwrap();
        write_evimo2_folder(dir.path(), with_depth);
        let recording = EvimoRecording::open(dir.path()).unwrap();
        assert_eq!(recording.layout(), EvimoLayout::Evimo2Folder);
        assert_eq!(recording.has_depth(), with_depth);
        check_frames(&recording, with_depth);
        // The folder is also an event input of its own.
        let mut reader = evgate_io::open(dir.path()).unwrap();
        assert_eq!(reader.format(), evgate_io::Format::Evimo2Folder);
        assert_eq!(read_all(reader.as_mut()).unwrap().len(), events().len());
    }
}

/// The same metadata saved by NumPy itself (fixtures/make_evimo_info_fixture.py): real pickles
/// with memo references, NumPy float64 scalars and ids beyond i64.
#[test]
fn a_dataset_info_written_by_numpy_is_read() {
    let dir = tempfile::tempdir().unwrap();
    write_evimo2_folder(dir.path(), true);
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/evimo2_dataset_info.npz"
        ),
        dir.path().join("dataset_info.npz"),
    )
    .unwrap();
    let recording = EvimoRecording::open(dir.path()).unwrap();
    check_frames(&recording, true);
}

fn write_single_npz(path: &Path, with_resolution: bool, frames_in_stack: usize) {
    let mut npz = NpzWriter::create(path, NpzCompression::Deflated).unwrap();
    let rows: Vec<f64> = events()
        .iter()
        .flat_map(|&(t, x, y, p)| [t, x as f64, y as f64, p as f64])
        .collect();
    npz.add("events", &[events().len(), 4], &rows).unwrap();
    let masks: Vec<u16> = (0..frames_in_stack)
        .flat_map(|i| {
            if GT_FRAMES.contains(&i) {
                raw_mask(i)
            } else {
                vec![0; WIDTH * HEIGHT]
            }
        })
        .collect();
    let depths: Vec<u16> = (0..frames_in_stack).flat_map(raw_depth).collect();
    npz.add("mask", &[frames_in_stack, HEIGHT, WIDTH], &masks)
        .unwrap();
    npz.add("depth", &[frames_in_stack, HEIGHT, WIDTH], &depths)
        .unwrap();
    npz.add_array("meta", &object_array(&meta(with_resolution)))
        .unwrap();
    npz.finish().unwrap();
}

#[test]
fn single_npz_streams_the_frame_stacks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dataset.npz");
    write_single_npz(&path, false, FRAME_TS.len());
    let recording = EvimoRecording::open(&path).unwrap();
    assert_eq!(recording.layout(), EvimoLayout::SingleNpz);
    check_frames(&recording, true);
}

fn write_png(path: &Path, mask: &[u16], depth: &[u16]) {
    let file = File::create(path).unwrap();
    let mut encoder = png::Encoder::new(file, WIDTH as u32, HEIGHT as u32);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().unwrap();
    let data: Vec<u8> = mask
        .iter()
        .zip(depth)
        .flat_map(|(&m, &d)| {
            let mut px = Vec::with_capacity(6);
            px.extend_from_slice(&m.to_be_bytes());
            px.extend_from_slice(&0u16.to_be_bytes());
            px.extend_from_slice(&d.to_be_bytes());
            px
        })
        .collect();
    writer.write_image_data(&data).unwrap();
}

fn write_text_folder(folder: &Path) {
    let mut meta = format!(
        "{{\n'meta': {{'fx': 200.0, 'res_x': {WIDTH}, 'res_y': {HEIGHT}, 'dist_model': 'radtan'}}\n, 'frames': [\n"
    );
    for (i, ts) in FRAME_TS.iter().enumerate() {
        meta.push_str(&format!("{{\n'id': {i},\t\t'ts': {ts:.6},\n'cam': {{'pos': {{'t': {{'x': 0.1}}}}, 'ts': {ts:.6}}},\n"));
        if GT_FRAMES.contains(&i) {
            meta.push_str(&format!("'gt_frame': 'depth_mask_{i}.png'\n"));
            write_png(
                &folder.join(format!("depth_mask_{i}.png")),
                &raw_mask(i),
                &raw_depth(i),
            );
        }
        meta.push_str("},\n");
    }
    meta.push_str("], 'full_trajectory': []\n}\n");
    std::fs::write(folder.join("meta.txt"), meta).unwrap();
    let text: String = events()
        .iter()
        .map(|&(t, x, y, p)| format!("{t:.9} {x} {y} {p}\n"))
        .collect();
    std::fs::write(folder.join("events.txt"), text).unwrap();
}

#[test]
fn text_folder_reads_meta_txt_and_depth_mask_pngs() {
    let dir = tempfile::tempdir().unwrap();
    write_text_folder(dir.path());
    let recording = EvimoRecording::open(dir.path()).unwrap();
    assert_eq!(recording.layout(), EvimoLayout::TextFolder);
    check_frames(&recording, true);
}

#[test]
fn bad_recordings_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let err = EvimoRecording::open(dir.path()).err().unwrap().to_string();
    assert!(
        err.contains("neither dataset_info.npz nor meta.txt") && err.contains("accepted"),
        "{err}"
    );

    // The metadata lists four frames, the stack holds three.
    let path = dir.path().join("short.npz");
    write_single_npz(&path, true, 3);
    let err = EvimoRecording::open(&path).err().unwrap().to_string();
    assert!(
        err.contains("short.npz") && err.contains("3 frames") && err.contains("lists 4"),
        "{err}"
    );

    // No meta array.
    let path = dir.path().join("nometa.npz");
    let mut npz = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
    npz.add("mask", &[1, HEIGHT, WIDTH], &raw_mask(0)).unwrap();
    npz.finish().unwrap();
    let err = EvimoRecording::open(&path).err().unwrap().to_string();
    assert!(
        err.contains("nometa.npz") && err.contains("no `meta` array"),
        "{err}"
    );

    // A mask of the wrong size in the EVIMO2 folder.
    let folder = dir.path().join("evimo2");
    std::fs::create_dir(&folder).unwrap();
    write_evimo2_folder(&folder, false);
    let mut masks =
        NpzWriter::create(folder.join("dataset_mask.npz"), NpzCompression::Stored).unwrap();
    masks
        .add(
            "mask_0000000000",
            &[HEIGHT, WIDTH + 1],
            &vec![0u16; HEIGHT * (WIDTH + 1)],
        )
        .unwrap();
    masks.finish().unwrap();
    let recording = EvimoRecording::open(&folder).unwrap();
    let err = recording
        .frames()
        .unwrap()
        .next()
        .unwrap()
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("mask_0000000000") && err.contains("[8, 13]") && err.contains("(8, 12)"),
        "{err}"
    );

    // A text folder whose meta.txt is cut short, and one whose PNG is missing.
    let text = dir.path().join("text");
    std::fs::create_dir(&text).unwrap();
    write_text_folder(&text);
    std::fs::remove_file(text.join("depth_mask_2.png")).unwrap();
    let recording = EvimoRecording::open(&text).unwrap();
    let results: Vec<_> = recording.frames().unwrap().collect();
    let err = results[1].as_ref().unwrap_err().to_string();
    assert!(
        err.contains("depth_mask_2.png") && err.contains("missing"),
        "{err}"
    );
    let meta = std::fs::read_to_string(text.join("meta.txt")).unwrap();
    std::fs::write(text.join("meta.txt"), &meta[..meta.len() / 2]).unwrap();
    let err = EvimoRecording::open(&text).err().unwrap().to_string();
    assert!(err.contains("meta.txt") && err.contains("byte"), "{err}");

    // A frame time that is not a number.
    std::fs::write(
        text.join("meta.txt"),
        meta.replacen("'ts': 0.056794", "'ts': 'soon'", 1),
    )
    .unwrap();
    let err = EvimoRecording::open(&text).err().unwrap().to_string();
    assert!(
        err.contains("frame 1") && err.contains("`ts`") && err.contains("soon"),
        "{err}"
    );
}

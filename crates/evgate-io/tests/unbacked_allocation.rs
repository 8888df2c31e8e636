//! Ground-truth frames whose headers claim more pixels than the file holds must not make the
//! EVIMO reader allocate for the claim: found while fuzzing the EVIMO readers (docs/fuzzing.md).
//! A counting global allocator records the largest single allocation of this test binary.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

use evgate_io::npy::{DType, NpyArray};
use evgate_io::npz::{NpzCompression, NpzWriter};
use evgate_io::EvimoRecording;

struct LargestAllocation;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for LargestAllocation {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        System.alloc(layout)
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        System.alloc_zeroed(layout)
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static ALLOCATOR: LargestAllocation = LargestAllocation;

/// Far above what these tiny inputs back, far below the gigabytes their headers claim.
const ALLOCATION_LIMIT: usize = 64 << 20;

/// `{'frames': [{'ts': 0.5}]}` as Python's `pickle.dumps(..., protocol=2)` writes it.
const ONE_FRAME_META: &[u8] =
    b"\x80\x02}q\x00X\x06\x00\x00\x00framesq\x01]q\x02}q\x03X\x02\x00\x00\x00tsq\x04G?\xe0\x00\x00\x00\x00\x00\x00sas.";

/// The tests run one at a time so each sees only its own allocations.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn measure_from_here() -> MutexGuard<'static, ()> {
    let guard = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    LARGEST.store(0, Ordering::Relaxed);
    guard
}

/// The error reading the first ground-truth frame of `recording` gives, after checking that no
/// allocation came near the size its header claims.
fn first_frame_error(recording: &Path) -> String {
    let recording = EvimoRecording::open(recording).unwrap();
    let frame = recording
        .frames()
        .unwrap()
        .next()
        .expect("one frame listed");
    let largest = LARGEST.load(Ordering::Relaxed);
    assert!(
        largest < ALLOCATION_LIMIT,
        "an allocation of {largest} bytes for an input of a few hundred"
    );
    frame.unwrap_err().to_string()
}

#[test]
fn a_mask_stack_claiming_50000x50000_frames_is_an_error_without_allocating_them() {
    let _measuring = measure_from_here();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("claims.npz");
    let mut npz = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
    let mask = NpyArray {
        dtype: DType::Scalar("<u2".into()),
        shape: vec![1, 50_000, 50_000],
        data: vec![0; 16],
    };
    npz.add_array("mask", &mask).unwrap();
    let meta = NpyArray {
        dtype: DType::Object,
        shape: vec![],
        data: ONE_FRAME_META.to_vec(),
    };
    npz.add_array("meta", &meta).unwrap();
    npz.finish().unwrap();

    let err = first_frame_error(&path);
    assert!(err.contains("mask"), "{err}");
}

fn write_png_header_claiming(path: &Path, width: u32, height: u32) {
    let file = std::fs::File::create(path).unwrap();
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().unwrap();
    // An empty zlib stream: the image data ends long before the claimed size.
    writer
        .write_chunk(
            png::chunk::IDAT,
            &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
        )
        .unwrap();
}

#[test]
fn a_png_claiming_60000x60000_pixels_is_an_error_without_allocating_them() {
    let _measuring = measure_from_here();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("meta.txt"),
        "{'meta': {'res_x': 12, 'res_y': 8}, 'frames': [{'ts': 0.5, 'gt_frame': 'depth_mask_0.png'}]}",
    )
    .unwrap();
    std::fs::write(dir.path().join("events.txt"), "0.1 1 2 1\n").unwrap();
    write_png_header_claiming(&dir.path().join("depth_mask_0.png"), 60_000, 60_000);

    let err = first_frame_error(dir.path());
    assert!(err.contains("60000x60000") && err.contains("12x8"), "{err}");
}

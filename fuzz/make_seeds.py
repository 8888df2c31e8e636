"""Writes starting inputs for the EVIMO fuzz targets into fuzz/corpus/<target>/ (ignored by
git), as NumPy itself saves the files (see docs/fuzzing.md). Needs numpy, e.g. the training
venv:

    models/training/.venv/bin/python fuzz/make_seeds.py
"""

import io
import struct
import zipfile
from pathlib import Path

import numpy as np

CORPUS = Path(__file__).with_name("corpus")
HEIGHT, WIDTH, FRAMES = 8, 12, 2


def meta(with_resolution: bool = True) -> dict:
    frames = [
        {"id": i, "ts": 0.01 + 0.025 * i, "gt_frame": f"depth_mask_{i}.png",
         "cam": {"pos": {"t": {"x": 0.1, "y": -0.2, "z": 0.3}}, "ts": 0.01 + 0.025 * i}}
        for i in range(FRAMES)
    ]
    camera = {"fx": 200.0, "dist_model": "radtan"}
    if with_resolution:
        camera.update(res_x=WIDTH, res_y=HEIGHT)
    return {"meta": camera, "frames": frames, "full_trajectory": frames}


def single_npz(compressed: bool, with_resolution: bool = True) -> bytes:
    events = np.array([[0.001 * i, i % WIDTH, i % HEIGHT, i % 2] for i in range(6)], np.float64)
    mask = np.zeros((FRAMES, HEIGHT, WIDTH), np.uint16)
    mask[:, 2:5, 3:7] = 1000
    depth = np.full((FRAMES, HEIGHT, WIDTH), 1500, np.uint16)
    out = io.BytesIO()
    save = np.savez_compressed if compressed else np.savez
    save(out, events=events, mask=mask, depth=depth, meta=meta(with_resolution))
    return out.getvalue()


def npy(array: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, array)
    return out.getvalue()


def write(target: str, name: str, data: bytes) -> None:
    folder = CORPUS / target
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(data)
    print(f"{folder / name}: {len(data)} bytes")


def main() -> None:
    write("evimo_npz", "seed-stored.npz", single_npz(False))
    write("evimo_npz", "seed-deflated.npz", single_npz(True))
    # Without res_x/res_y the frame size comes from the mask header alone.
    write("evimo_npz", "seed-no-resolution.npz", single_npz(False, with_resolution=False))
    with zipfile.ZipFile(io.BytesIO(single_npz(False))) as archive:
        meta_npy = archive.read("meta.npy")
    header_length = struct.unpack("<H", meta_npy[8:10])[0]
    write("evimo_meta_pickle", "seed.pickle", meta_npy[10 + header_length:])
    write("evimo_meta_txt", "seed-meta.txt", repr(meta()).encode())
    n = 5
    t = npy(np.arange(n, dtype=np.float64) * 1e-3)
    xy = npy(np.stack([np.arange(n) % WIDTH, np.arange(n) % HEIGHT], 1).astype(np.uint16))
    p = npy((np.arange(n) % 2).astype(np.uint8))
    write("evimo2_npy", "seed", struct.pack("<HH", len(t), len(xy)) + t + xy + p)


if __name__ == "__main__":
    main()

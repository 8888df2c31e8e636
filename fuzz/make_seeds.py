"""Writes the committed seed corpus, fuzz/seeds/<target>/, of every fuzz target (see
docs/fuzzing.md): prefixes of the real recordings in ../shared/data for the byte-stream
decoders, small files written here for the text, DAT and .evg formats, and files NumPy itself
saves for the EVIMO and .npy targets. Needs numpy, e.g. the training venv:

    models/training/.venv/bin/python fuzz/make_seeds.py
"""

import io
import struct
import zipfile
from pathlib import Path

import numpy as np

CORPUS = Path(__file__).with_name("seeds")
REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
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


def prophesee_prefix(name: str, header_lines: int, words: int, word_bytes: int) -> bytes:
    """The `%` header of a real RAW file and its first `words` words."""
    data = (REAL / name).read_bytes()
    end = 0
    for _ in range(header_lines):
        if not data[end:].startswith(b"%"):
            break
        end = data.index(b"\n", end) + 1
    return data[: end + words * word_bytes]


def dat_file() -> bytes:
    header = b"% Date 2020-01-01\n% Height 8\n% Width 12\n"
    records = b"".join(
        struct.pack("<II", 100 * i, (i % 12) | ((i % 8) << 14) | ((i % 2) << 28))
        for i in range(6)
    )
    return header + bytes([0, 8]) + records


def native_file() -> bytes:
    """An .evg as `evgate convert` writes it, read back from the prefix of its first bytes."""
    import subprocess
    import tempfile

    root = Path(__file__).resolve().parents[1]
    binary = root / "target" / "debug" / "evgate"
    with tempfile.TemporaryDirectory() as scratch:
        text = Path(scratch) / "in.csv"
        text.write_text("".join(f"{10 * i},{i % 12},{i % 8},{i % 2}\n" for i in range(8)))
        out = Path(scratch) / "out.evg"
        subprocess.run(
            [str(binary), "convert", "--sensor", "12x8", str(text), str(out)], check=True,
            capture_output=True,
        )
        return out.read_bytes()


def main() -> None:
    write("evt2", "seed-evt2.raw", prophesee_prefix("evt2_sample.raw", 64, 1024, 4))
    write("evt3", "seed-evt3.raw", prophesee_prefix("evt3_sample.raw", 64, 2048, 2))
    write("aedat4", "seed.aedat4", (REAL / "sample.aedat4").read_bytes()[:12_000])
    write("dat", "seed.dat", dat_file())
    write("csv", "seed.csv", b"t,x,y,p\n10,1,2,1\n# note\n0.5 3 4 -1\n12,5,6,0\n")
    write("native", "seed.evg", native_file())
    write("npy", "seed-scalar.npy", npy(np.arange(6, dtype=np.int64)))
    record = np.zeros(3, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    write("npy", "seed-record.npy", npy(record))
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

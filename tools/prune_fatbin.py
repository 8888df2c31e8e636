#!/usr/bin/env python3
"""Zeroes the GPU machine code for other architectures in a CUDA shared library's fat binary.

ONNX Runtime's CUDA provider (`libonnxruntime_providers_cuda.so`, 284 MB) carries compiled
kernels (cubins) for sm_75 to sm_120; a GPU loads only those of its own architecture. A GPU
lease moves at most 64 MiB per call into a machine that starts bare, so the library travels in
parts: with the cubins of every other architecture zeroed it compresses from 187 MB to 52 MB
(xz), three calls fewer. Entry headers, sizes, offsets and PTX are kept, so the file keeps its
layout and the driver still finds the entries; only the payloads it would never load for the
kept architecture become zeros.

Usage: prune_fatbin.py IN OUT [--keep-arch 90 ...]
"""

import argparse
import struct
import sys
from pathlib import Path

FATBIN_MAGIC = 0xBA55ED50
FATBIN_SECTION = b".nv_fatbin"
ENTRY_KIND_CUBIN = 2
# A fat-binary blob header: magic u32, version u16, header size u16, payload size u64.
BLOB_HEADER = struct.Struct("<IHHQ")
# An entry header starts with kind u16, (unused) u16, header size u32, payload size u64; the
# architecture (e.g. 90 for sm_90) is the u32 at byte 28.
ENTRY_HEADER = struct.Struct("<HHIQ")
ENTRY_ARCH_OFFSET = 28
# Blobs in the section are 8-byte aligned.
BLOB_ALIGNMENT = 8


class FatbinError(ValueError):
    """A library this tool cannot prune, with the reason."""


def fatbin_section(data: bytes | bytearray, path: Path) -> tuple[int, int]:
    """(offset, size) of the `.nv_fatbin` section of an ELF64 little-endian file."""
    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise FatbinError(f"{path}: not a 64-bit little-endian ELF file")
    section_headers = struct.unpack_from("<Q", data, 0x28)[0]
    entry_size, count, names_index = struct.unpack_from("<HHH", data, 0x3A)
    sections = [
        struct.unpack_from("<IIQQQQ", data, section_headers + i * entry_size) for i in range(count)
    ]
    names_offset = sections[names_index][4]
    for name, _, _, _, offset, size in sections:
        start = names_offset + name
        if data[start : data.index(b"\0", start)] == FATBIN_SECTION:
            return offset, size
    raise FatbinError(f"{path}: no .nv_fatbin section (no CUDA machine code to prune)")


def prune(data: bytearray, path: Path, keep: set[int]) -> dict[str, int]:
    """Zeroes in place the cubin payloads whose architecture is not in `keep`; returns counts."""
    offset, size = fatbin_section(data, path)
    end = offset + size
    counts = {"kept": 0, "zeroed": 0, "kept_bytes": 0, "zeroed_bytes": 0, "blobs": 0}
    position = offset
    while position + BLOB_HEADER.size <= end:
        magic, _, header_size, payload_size = BLOB_HEADER.unpack_from(data, position)
        if magic != FATBIN_MAGIC:
            position += BLOB_ALIGNMENT
            continue
        counts["blobs"] += 1
        entry = position + header_size
        blob_end = entry + payload_size
        if blob_end > end:
            raise FatbinError(f"{path}: fat binary at byte {position} runs past its section")
        while entry < blob_end:
            kind, _, entry_header_size, entry_size = ENTRY_HEADER.unpack_from(data, entry)
            arch = struct.unpack_from("<I", data, entry + ENTRY_ARCH_OFFSET)[0]
            payload = entry + entry_header_size
            if payload + entry_size > blob_end or entry_header_size < ENTRY_ARCH_OFFSET + 4:
                raise FatbinError(f"{path}: malformed fat-binary entry at byte {entry}")
            if kind == ENTRY_KIND_CUBIN and arch not in keep:
                data[payload : payload + entry_size] = bytes(entry_size)
                counts["zeroed"] += 1
                counts["zeroed_bytes"] += entry_size
            else:
                counts["kept"] += 1
                counts["kept_bytes"] += entry_size
            entry = payload + entry_size
        position = blob_end
    if counts["blobs"] == 0:
        raise FatbinError(f"{path}: .nv_fatbin holds no fat binary (magic {FATBIN_MAGIC:#x} not found)")
    if counts["kept"] == 0:
        raise FatbinError(f"{path}: no machine code for sm_{'/'.join(map(str, sorted(keep)))}; nothing would run")
    return counts


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("input", type=Path, help="the CUDA shared library")
    parser.add_argument("output", type=Path, help="where to write the pruned copy")
    parser.add_argument(
        "--keep-arch",
        type=int,
        action="append",
        help="SM architecture whose cubins stay, e.g. 90 for the H100 and H200 (repeatable; default 90)",
    )
    args = parser.parse_args(argv)
    keep = set(args.keep_arch or [90])
    try:
        data = bytearray(args.input.read_bytes())
        try:
            counts = prune(data, args.input, keep)
        except (struct.error, ValueError, IndexError) as error:
            if isinstance(error, FatbinError):
                raise
            raise FatbinError(f"{args.input}: truncated or malformed ELF file ({error})") from error
    except (OSError, FatbinError) as error:
        print(f"prune_fatbin: {error}", file=sys.stderr)
        return 1
    args.output.write_bytes(data)
    print(
        f"{args.input} -> {args.output}: {counts['blobs']} fat binaries, kept {counts['kept']} entries "
        f"({counts['kept_bytes'] / 1e6:.1f} MB), zeroed {counts['zeroed']} cubins ({counts['zeroed_bytes'] / 1e6:.1f} MB)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

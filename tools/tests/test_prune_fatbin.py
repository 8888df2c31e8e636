import struct
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "prune_fatbin.py"
sys.path.insert(0, str(SCRIPT.parent))

from prune_fatbin import FATBIN_MAGIC, FatbinError, prune  # noqa: E402


def _entry(kind: int, arch: int, payload: bytes) -> bytes:
    header = bytearray(64)
    struct.pack_into("<HHIQ", header, 0, kind, 0x101, len(header), len(payload))
    struct.pack_into("<I", header, 28, arch)
    return bytes(header) + payload


def _blob(*entries: bytes) -> bytes:
    body = b"".join(entries)
    return struct.pack("<IHHQ", FATBIN_MAGIC, 1, 16, len(body)) + body


def _elf(fatbin: bytes) -> bytes:
    """A minimal ELF64 file: a null section, .nv_fatbin and the section-name table."""
    names = b"\0.nv_fatbin\0.shstrtab\0"
    fatbin_offset = 64
    names_offset = fatbin_offset + len(fatbin)
    headers_offset = names_offset + len(names)
    header = bytearray(64)
    header[:6] = b"\x7fELF\x02\x01"
    struct.pack_into("<Q", header, 0x28, headers_offset)
    struct.pack_into("<HHH", header, 0x3A, 64, 3, 2)

    def section(name: int, offset: int, size: int) -> bytes:
        return struct.pack("<IIQQQQIIQQ", name, 1, 0, 0, offset, size, 0, 0, 1, 0)

    sections = bytes(64) + section(1, fatbin_offset, len(fatbin)) + section(12, names_offset, len(names))
    return bytes(header) + fatbin + names + sections


SM80 = b"\x80" * 40
SM90 = b"\x90" * 48
PTX = b"ptx-text" * 3


def _library() -> bytearray:
    # Two blobs with 8 bytes of alignment padding between them, as in real libraries.
    return bytearray(_elf(_blob(_entry(2, 80, SM80), _entry(2, 90, SM90)) + bytes(8) + _blob(_entry(1, 80, PTX))))


def test_other_architectures_become_zeros_and_the_layout_stays():
    original = _library()
    pruned = bytearray(original)
    counts = prune(pruned, Path("lib.so"), {90})
    assert len(pruned) == len(original)
    assert SM80 not in pruned and bytes(len(SM80)) in pruned
    assert SM90 in pruned and PTX in pruned
    assert counts["zeroed"] == 1 and counts["kept"] == 2 and counts["blobs"] == 2
    # Only payload bytes change: every header is where and what it was.
    changed = [i for i, (a, b) in enumerate(zip(original, pruned)) if a != b]
    start = original.index(SM80)
    assert changed == list(range(start, start + len(SM80)))


def test_a_library_without_the_kept_architecture_is_refused():
    cubins_only = bytearray(_elf(_blob(_entry(2, 80, SM80), _entry(2, 90, SM90))))
    with pytest.raises(FatbinError, match="no machine code for sm_75"):
        prune(cubins_only, Path("lib.so"), {75})


def test_ptx_counts_as_code_that_runs():
    # The driver compiles PTX for a newer GPU, so a library with PTX is never left without code.
    counts = prune(_library(), Path("lib.so"), {75})
    assert counts["zeroed"] == 2 and counts["kept"] == 1


def test_a_file_without_a_fat_binary_is_refused_by_name():
    with pytest.raises(FatbinError, match=r"lib\.so: no \.nv_fatbin section"):
        prune(bytearray(_elf(b"").replace(b".nv_fatbin", b".nv_rodata")), Path("lib.so"), {90})


def test_the_command_reports_bad_input_without_writing(tmp_path):
    not_elf = tmp_path / "notes.txt"
    not_elf.write_text("hello")
    output = tmp_path / "out.so"
    result = subprocess.run([sys.executable, str(SCRIPT), str(not_elf), str(output)], capture_output=True, text=True)
    assert result.returncode == 1
    assert "notes.txt: not a 64-bit little-endian ELF file" in result.stderr
    assert not output.exists()
    truncated = tmp_path / "truncated.so"
    truncated.write_bytes(_library()[:80])
    result = subprocess.run([sys.executable, str(SCRIPT), str(truncated), str(output)], capture_output=True, text=True)
    assert result.returncode == 1 and "truncated.so" in result.stderr and not output.exists()


def test_the_command_writes_the_pruned_copy(tmp_path):
    library = tmp_path / "lib.so"
    library.write_bytes(_library())
    output = tmp_path / "pruned.so"
    result = subprocess.run([sys.executable, str(SCRIPT), str(library), str(output), "--keep-arch", "90"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "zeroed 1 cubins" in result.stdout
    assert SM90 in output.read_bytes() and SM80 not in output.read_bytes()

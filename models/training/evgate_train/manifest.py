"""Writes the manifest of a set of training sequences: each file's relative path, size and
SHA-256 plus its preset and seed, so the hash stored in an exported model pins its data.

    python -m evgate_train.manifest --data ../../data/suite/train --output ../../data/suite/train-manifest.json

Use the simulator suite's own manifest instead where it writes one.
"""

import argparse
import hashlib
import json
import sys
from pathlib import Path

from tqdm import tqdm

from .sequence import load_sequence


class ManifestError(ValueError):
    """No sequence to list."""


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def build_manifest(data: Path) -> dict:
    paths = sorted(data.rglob("*.npz"))
    if not paths:
        raise ManifestError(f"{data}: no .npz sequences found")
    entries = []
    for path in tqdm(paths, desc="manifest", unit="seq"):
        sequence = load_sequence(path)
        entries.append(
            {
                "path": str(path.relative_to(data)),
                "preset": sequence.preset,
                "seed": sequence.meta.get("seed"),
                "duration-us": sequence.meta.get("duration-us"),
                "bytes": path.stat().st_size,
                "sha256": file_sha256(path),
            }
        )
    return {"format": "evgate-train-manifest/1", "sequences": entries}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="directory searched recursively for .npz sequences")
    parser.add_argument("--output", type=Path, required=True, help="manifest JSON to write")
    args = parser.parse_args(argv)
    manifest = build_manifest(args.data)
    args.output.write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"{args.output}: {len(manifest['sequences'])} sequences, sha256 {file_sha256(args.output)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Regenerate the committed Python code for the wire contract.

Run from anywhere:  python -m protos.regenerate   (needs grpcio-tools)

The .proto files live in protos/communicator_objects/ and import each other by their
repository path, so the generated modules import ``protos.communicator_objects.*``.
``--check`` regenerates into a temporary folder and exits 1 if anything differs from
what is committed (tests/protocol/test_protos.py runs it).
"""
from __future__ import annotations

import argparse
import filecmp
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROTO_DIR = ROOT / "protos" / "communicator_objects"


def generate(out_root: Path) -> list[Path]:
    from grpc_tools import protoc  # imported here: only needed when regenerating
    import grpc_tools

    protos = sorted(PROTO_DIR.glob("*.proto"))
    include = Path(grpc_tools.__file__).parent / "_proto"
    args = [
        "protoc",
        f"-I{ROOT}",
        f"-I{include}",
        f"--python_out={out_root}",
        f"--pyi_out={out_root}",
        f"--grpc_python_out={out_root}",
        *[str(p.relative_to(ROOT)) for p in protos],
    ]
    if protoc.main(args) != 0:
        raise SystemExit("protoc failed")
    gen_dir = out_root / "protos" / "communicator_objects"
    return sorted(p for p in gen_dir.iterdir() if p.suffix in (".py", ".pyi"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare instead of writing")
    ns = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        files = generate(Path(tmp))
        changed = []
        for f in files:
            dest = PROTO_DIR / f.name
            if not dest.exists() or not filecmp.cmp(f, dest, shallow=False):
                changed.append(f.name)
                if not ns.check:
                    shutil.copyfile(f, dest)
    if ns.check and changed:
        print("generated code is stale: " + ", ".join(changed), file=sys.stderr)
        return 1
    if not ns.check:
        print(f"regenerated {len(files)} files" + (f", changed: {', '.join(changed)}" if changed else ", no change"))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Builds swarf_client, generating its gRPC stubs from the repository's
proto/ (or $SWARF_PROTO_DIR) with grpc_tools.protoc at build time: nothing
generated is kept in the source tree."""

import os
import pathlib
import re
import shutil
import tempfile

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = pathlib.Path(__file__).resolve().parent
PROTO = "swarf/v1/swarf.proto"


def proto_root() -> pathlib.Path:
    root = pathlib.Path(os.environ.get("SWARF_PROTO_DIR", HERE.parent.parent / "proto"))
    if not (root / PROTO).is_file():
        raise SystemExit(
            f"swarf_client: {root / PROTO} not found: build from the swarf "
            "repository, or set SWARF_PROTO_DIR to its proto/ directory")
    return root


def generate(out_dir: pathlib.Path) -> None:
    """Writes swarf_pb2.py and swarf_pb2_grpc.py into out_dir as modules of
    the package swarf_client._proto (internal: the public API is typed)."""
    from grpc_tools import protoc  # Debian: python3-grpc-tools

    root = proto_root()
    includes = pathlib.Path(protoc.__file__).parent / "_proto"
    with tempfile.TemporaryDirectory() as tmp:
        args = ["grpc_tools.protoc", f"-I{root}", f"-I{includes}",
                f"--python_out={tmp}", f"--grpc_python_out={tmp}",
                str(root / PROTO)]
        if protoc.main(args) != 0:
            raise SystemExit("swarf_client: protoc failed on " + PROTO)
        out_dir.mkdir(parents=True, exist_ok=True)
        gen = pathlib.Path(tmp) / "swarf" / "v1"
        for name in ("swarf_pb2.py", "swarf_pb2_grpc.py"):
            text = (gen / name).read_text()
            # The stubs import each other as top-level swarf.v1: make them
            # relative so that they live inside this package.
            text = re.sub(r"^from swarf\.v1 import", "from . import", text,
                          flags=re.M)
            (out_dir / name).write_text(text)
            # Debian's protoc has no .pyi generator: type checkers see the
            # generated modules as Any rather than as untyped.
            (out_dir / name).with_suffix(".pyi").write_text(
                "from typing import Any\n\n"
                "def __getattr__(name: str) -> Any: ...\n")
        (out_dir / "__init__.py").write_text(
            '"""gRPC stubs generated from proto/swarf/v1/swarf.proto."""\n')


class BuildPyWithStubs(build_py):
    def run(self) -> None:
        super().run()
        generate(pathlib.Path(self.build_lib) / "swarf_client" / "_proto")


setup(cmdclass={"build_py": BuildPyWithStubs})

"""Generates the landscape.v1 stubs from proto/ before packaging (stubs are never committed)."""
from pathlib import Path

from setuptools import setup

ROOT = Path(__file__).parent


def generate_stubs() -> None:
    from grpc_tools import protoc  # build requirement, see pyproject.toml
    import grpc_tools

    out = ROOT / "gen"
    package = out / "landscape" / "v1"
    package.mkdir(parents=True, exist_ok=True)
    protos = sorted(str(p.relative_to(ROOT / "proto")) for p in (ROOT / "proto").rglob("*.proto"))
    well_known = str(Path(grpc_tools.__file__).parent / "_proto")
    args = ["protoc", "-Iproto", f"-I{well_known}", f"--python_out={out}", f"--pyi_out={out}",
            f"--grpc_python_out={out}", *protos]
    if protoc.main(args) != 0:
        raise RuntimeError("protoc failed on " + " ".join(protos))
    (package / "__init__.py").touch()


if __name__ == "__main__":
    # Every build (wheel, sdist, editable) runs this file first, and the package directory
    # gen/landscape/v1 must exist before setuptools looks for it.
    generate_stubs()
    setup()

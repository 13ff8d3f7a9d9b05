"""Generates the landscape.v1 stubs from proto/ before packaging (stubs are never committed)."""
from pathlib import Path

from setuptools import find_packages, setup

ROOT = Path(__file__).parent

# The top-level folders of the repository are sub-packages of one import name, `landscape`.
PACKAGE_DIR = {"landscape.v1": "gen/landscape/v1", "landscape.server": "server",
               "landscape.robot": "robot", "landscape.sim": "sim",
               "landscape.client": "client", "landscape.gateway": "gateway",
               "landscape.supervisor": "supervisor_gui_web", "landscape.cell": "cell",
               "landscape.bridges": "bridges"}
# Every folder holding data files is a package of its own, or setuptools warns (at length) that
# it "would be ignored".
PACKAGE_DATA = {"landscape.robot.cells": ["*.toml"], "landscape.cell.cells": ["*.toml"]}
PAGE = ROOT / "supervisor_gui_web" / "frontend" / "dist"   # the web supervisor's built page


def page_packages() -> dict[str, list[str]]:
    """The built page's folders as packages with all their files, {} before npm built it
    (`make install` does; the web supervisor then says the page is not built)."""
    if not (PAGE / "index.html").is_file():
        return {}
    folders = [PAGE, *(p for p in sorted(PAGE.rglob("*")) if p.is_dir())]
    return {".".join(["landscape.supervisor", *f.relative_to(PAGE.parents[1]).parts]): ["*"]
            for f in folders}


def packages() -> list[str]:
    """Every folder with an __init__.py under a top-level folder, found (setuptools looks only
    inside packages, so the page's node_modules is never walked), and the data folders."""
    found = []
    for name, folder in PACKAGE_DIR.items():
        found += [name, *(f"{name}.{sub}" for sub in find_packages(where=ROOT / folder))]
    return sorted({*found, *PACKAGE_DATA})


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
    page = page_packages()
    setup(packages=packages() + list(page), package_dir=PACKAGE_DIR,
          package_data=PACKAGE_DATA | page)

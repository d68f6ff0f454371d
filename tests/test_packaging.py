"""The wheel is the product: built from the sources and installed, it serves the dashboard.

The slow tests build the wheel from a copy of the sources, install it with pip into a fresh
virtual environment and start that environment's ``deltadash serve`` from a folder outside
the checkout, with no PYTHONPATH. The wheel is installed without its dependencies (fetching
NumPy, MuJoCo, ... would take minutes): a ``.pth`` line lends the venv this interpreter's
site-packages. A ``.pth`` line only extends sys.path, it runs no other ``.pth`` there, so the
editable install of the checkout stays invisible; the tests check that ``app`` and the
dashboard are imported from the venv.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import site
import socket
import subprocess
import sys
import sysconfig
import time
import tomllib
import urllib.error
import urllib.request
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.support.browser import chromium_page

REPO = Path(__file__).resolve().parents[1]
STATIC = REPO / "static"
SHIPPED = ("app", "hardware", "kinematics")
STATIC_PACKAGE = "deltadash_static"
GENERATED = shutil.ignore_patterns("__pycache__", "*.egg-info", ".*_cache", ".hypothesis")
# Only at the top: app/runs/ is a package, runs/ the run logs.
NOT_SOURCES_AT_TOP = {".git", ".venv", "venv", "build", "dist", "runs", "artifacts"}
ASSET = re.compile(r"""(?:src|href)=["']([^"']+)["']""")
BUILD_S = 600.0  # pip fetches setuptools for the isolated build
START_S = 120.0  # the simulator starts slowly on a loaded 2-core machine


def source_packages() -> set[str]:
    """Every package the wheel must hold: folders with Python under app/, hardware/,
    kinematics/, and static/ with its subfolders as ``deltadash_static``."""
    names = set()
    for top in SHIPPED:
        for module in (REPO / top).rglob("*.py"):
            folder = module.parent.relative_to(REPO)
            if "__pycache__" not in folder.parts:
                names.add(".".join(folder.parts))
    for folder in [STATIC, *STATIC.rglob("*")]:
        parts = folder.relative_to(STATIC).parts
        if folder.is_dir() and "__pycache__" not in parts:
            names.add(".".join((STATIC_PACKAGE, *parts)))
    return names


def dashboard_files() -> set[str]:
    """static/'s files as the wheel must hold them (the page, not the package marker)."""
    return {
        "/".join((STATIC_PACKAGE, *path.relative_to(STATIC).parts))
        for path in STATIC.rglob("*")
        if path.is_file()
        and "__pycache__" not in path.parts
        and path.name not in (".gitkeep", "__init__.py")
    }


def test_pyproject_lists_every_package():
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    listed = set(pyproject["tool"]["setuptools"]["packages"])
    missing, gone = source_packages() - listed, listed - source_packages()
    assert not missing, f"add to [tool.setuptools] packages in pyproject.toml: {sorted(missing)}"
    assert not gone, f"listed in pyproject.toml but not in the sources: {sorted(gone)}"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_for(condition: Callable[[], Any], what: str, timeout_s: float) -> Any:
    """Poll ``condition`` until it returns something truthy; fail naming ``what``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def run(command: list[str | Path], cwd: Path, env: dict[str, str] | None = None) -> str:
    done = subprocess.run(
        [str(c) for c in command],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=BUILD_S,
    )
    assert done.returncode == 0, f"{command} failed:\n{done.stdout[-2000:]}{done.stderr[-3000:]}"
    return done.stdout


def build_wheel(work: Path) -> Path:
    """The wheel pip builds from a copy of the sources (no stale build/ from the checkout)."""
    sources = work / "src"

    def not_sources(folder: str, names: list[str]) -> set[str]:
        top = NOT_SOURCES_AT_TOP if Path(folder) == REPO else set()
        return GENERATED(folder, names) | (top & set(names))

    shutil.copytree(REPO, sources, ignore=not_sources)
    pip_wheel = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", work / "dist"]
    run([*pip_wheel, "."], sources, clean_env())
    (wheel,) = (work / "dist").glob("deltadash-*.whl")
    return wheel


def lent_site_packages() -> list[str]:
    """This interpreter's site-packages: the installed wheel's dependencies."""
    paths = [*site.getsitepackages(), sysconfig.get_path("purelib"), sysconfig.get_path("platlib")]
    return list(dict.fromkeys(p for p in paths if Path(p).is_dir()))


def install_into_fresh_venv(wheel: Path, venv: Path) -> Path:
    """``venv``'s python with ``wheel`` installed by pip and the dependencies lent."""
    run([sys.executable, "-m", "venv", "--without-pip", venv], venv.parent)
    python = venv / "bin" / "python"
    pip = [sys.executable, "-m", "pip", "--python", python]
    run([*pip, "install", "--no-deps", "--no-index", "-q", wheel], venv.parent, clean_env())
    purelib = run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], venv)
    (Path(purelib.strip()) / "deltadash-test-deps.pth").write_text(
        "\n".join(lent_site_packages()) + "\n"
    )
    return python


def clean_env() -> dict[str, str]:
    """This environment without anything that points Python or deltadash elsewhere."""
    return {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("PYTHON", "DELTADASH_", "VIRTUAL_ENV"))
    }


PROBE = """
import json, app, deltadash_static
from app.static_files import static_dir
print(json.dumps({"app": app.__file__, "static": str(static_dir())}))
"""


@dataclass
class Installed:
    """A ``deltadash serve`` from the fresh venv, and where its code came from."""

    url: str
    venv: Path
    wheel: Path
    imported: dict[str, str]

    def fetch(self, path: str) -> tuple[int, str, bytes]:
        try:
            with urllib.request.urlopen(self.url + path, timeout=10) as response:
                return response.status, response.headers.get_content_type(), response.read()
        except urllib.error.HTTPError as exc:
            return exc.code, "", b""

    def up(self) -> bool:
        try:
            return self.fetch("/api/status")[0] == 200
        except (urllib.error.URLError, OSError):
            return False


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Iterator[Installed]:
    work = tmp_path_factory.mktemp("wheel")
    wheel = build_wheel(work)
    python = install_into_fresh_venv(wheel, work / "venv")
    outside = work / "elsewhere"  # the cwd: neither the checkout nor its copy
    outside.mkdir()
    env = clean_env()
    imported = json.loads(run([python, "-c", PROBE], outside, env))
    port = free_port()
    config = outside / "serve.toml"
    config.write_text(
        f"[server]\nhttp_port = {port}\nviser_port = {free_port()}\nscene = false\n"
        f'[runs]\nfolder = "{outside / "runs"}"\n'
    )
    log = work / "serve.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [work / "venv" / "bin" / "deltadash", "serve", "--config", config],
            cwd=outside,
            env=env,
            stdout=out,
            stderr=out,
        )
    served = Installed(f"http://127.0.0.1:{port}", work / "venv", wheel, imported)
    try:
        end = time.monotonic() + START_S
        while not served.up():
            if process.poll() is not None or time.monotonic() > end:
                tail = log.read_text()[-3000:]
                pytest.fail(f"the installed deltadash serve did not start:\n{tail}")
            time.sleep(0.5)
        yield served
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def local_assets(html: str, page: str) -> list[str]:
    assets = ASSET.findall(html)
    for asset in assets:
        assert not re.match(r"(https?:)?//", asset), f"{page} loads {asset} from outside"
    return assets


@pytest.mark.slow
def test_the_server_runs_the_installed_copy_not_the_checkout(installed: Installed):
    for name, path in installed.imported.items():
        assert Path(path).is_relative_to(installed.venv), f"{name} came from {path}"
        assert not Path(path).is_relative_to(REPO), f"{name} came from the checkout: {path}"


@pytest.mark.slow
def test_the_wheel_holds_every_dashboard_file(installed: Installed):
    with zipfile.ZipFile(installed.wheel) as wheel:
        shipped = {name for name in wheel.namelist() if name.startswith(STATIC_PACKAGE + "/")}
    assert dashboard_files() <= shipped, f"missing: {sorted(dashboard_files() - shipped)}"


@pytest.mark.slow
def test_the_installed_server_serves_the_dashboard_and_its_status(installed: Installed):
    status, kind, body = installed.fetch("/")
    assert status == 200 and kind == "text/html", (status, kind)
    html = body.decode()
    assert "<title>deltadash</title>" in html
    for asset in local_assets(html, "/"):
        if asset != "#":
            path = asset if asset.startswith("/") else "/" + asset  # relative to /
            assert installed.fetch(path)[0] == 200, f"the dashboard's {asset} is not served"
    status, kind, body = installed.fetch("/api/status")
    assert status == 200 and kind == "application/json", (status, kind)
    assert "mode" in json.loads(body)
    assert installed.fetch("/vendor/plotly.min.js")[0] == 200


@pytest.mark.slow
def test_the_installed_docs_load_nothing_from_outside(installed: Installed):
    status, _, body = installed.fetch("/docs")
    assert status == 200
    html = body.decode()
    assert "http://" not in html and "https://" not in html, "/docs names an external URL"
    for asset in local_assets(html, "/docs"):
        assert installed.fetch(asset)[0] == 200, f"/docs needs {asset}, which is not served"


@pytest.mark.slow
@pytest.mark.browser
def test_docs_render_with_the_network_off(installed: Installed):
    """Swagger UI draws the API's operations while every request off this server fails."""
    with chromium_page() as page:
        blocked: list[str] = []

        def offline(route: Any) -> None:
            if route.request.url.startswith(installed.url):
                route.continue_()
            else:
                blocked.append(route.request.url)
                route.abort("internetdisconnected")

        page.route("**/*", offline)
        page.goto(installed.url + "/docs")
        page.wait_for_selector(".opblock", timeout=60_000)  # one block per route
        assert page.locator(".opblock").count() > 10
        assert not blocked, f"/docs asked for outside resources: {blocked}"

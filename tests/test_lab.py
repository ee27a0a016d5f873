"""``make lab``: JupyterLab on notebooks/ with jupytext's contents manager, checked through the REST API of a
server started on a free loopback port with a token (and always stopped, whatever the test's outcome)."""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import time
import urllib.error
import urllib.request

import pytest

from conftest import REPO

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="GNU make not installed")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _stop(proc: subprocess.Popen) -> None:
    """SIGTERM to make (which passes it on to jupyter and waits for it), then SIGKILL to the whole process
    group if anything is left after 30 s."""
    if proc.poll() is None:
        proc.terminate()
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=30)
    deadline = time.monotonic() + 30
    while _group_alive(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    if _group_alive(proc.pid):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


class Lab:
    """A running ``make lab`` server: its base URL and token."""

    def __init__(self, url: str, token: str, proc: subprocess.Popen, log) -> None:
        self.url, self.token, self.proc, self.log = url, token, proc, log

    def get(self, path: str, auth: bool = True):
        """(final URL, decoded JSON or None) of a GET of ``path``."""
        req = urllib.request.Request(self.url + path, headers={"Authorization": f"token {self.token}"} if auth else {})
        with urllib.request.urlopen(req, timeout=30) as r:
            body = r.read()
            return r.geturl(), (json.loads(body) if r.headers.get_content_type() == "application/json" else None)


@contextlib.contextmanager
def _make_lab(tmp_path):
    port, token = _free_port(), secrets.token_hex(16)
    # the user's Jupyter config and runtime files stay out of it
    env = {**os.environ, "JUPYTER_CONFIG_DIR": str(tmp_path / "config"), "JUPYTER_RUNTIME_DIR": str(tmp_path / "rt")}
    args = f"--no-browser --ServerApp.ip=127.0.0.1 --port={port} --ServerApp.port_retries=0 " \
           f"--IdentityProvider.token={token}"
    log_path = tmp_path / "lab.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(["make", "--no-print-directory", "lab", f"LAB_ARGS={args}"], cwd=REPO, env=env,
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    lab = Lab(f"http://127.0.0.1:{port}", token, proc, log_path)
    try:
        deadline = time.monotonic() + 180
        while True:
            if proc.poll() is not None:
                pytest.fail(f"make lab exited ({proc.returncode}):\n{log_path.read_text()[-3000:]}")
            try:
                lab.get("/api/status")
                break
            except (urllib.error.URLError, ConnectionError, TimeoutError):
                if time.monotonic() > deadline:
                    pytest.fail(f"make lab did not answer within 180 s:\n{log_path.read_text()[-3000:]}")
                time.sleep(0.25)
        yield lab
    finally:
        _stop(proc)


def test_make_lab_serves_the_notebook_sources_as_notebooks(tmp_path):
    import jupytext

    with _make_lab(tmp_path) as lab:
        # no token, no access
        with pytest.raises(urllib.error.HTTPError) as e:
            lab.get("/api/contents/notebooks", auth=False)
        assert e.value.code == 403
        # the start page is notebooks/
        url, _ = lab.get("/")
        assert url.endswith("/lab/tree/notebooks"), url
        _, listing = lab.get("/api/contents/notebooks")
        assert listing["type"] == "directory"
        kinds = {c["name"]: c["type"] for c in listing["content"]}
        sources = sorted(p.name for p in (REPO / "notebooks").glob("[0-9][0-9]_*.py"))
        assert len(sources) >= 9 and all(kinds.get(n) == "notebook" for n in sources), kinds  # jupytext's manager
        src = REPO / "notebooks" / "01_generate_dataset.py"
        _, model = lab.get("/api/contents/notebooks/01_generate_dataset.py?type=notebook&content=1")
        assert model["type"] == "notebook" and model["format"] == "json"
        cells = model["content"]["cells"]
        expected = jupytext.read(src).cells
        assert len(cells) == len(expected) > 2
        assert [c["cell_type"] for c in cells] == [c.cell_type for c in expected]
        assert cells[0]["cell_type"] == "markdown" and cells[0]["source"].startswith("# 01 ")
        assert any("parameters" in c["metadata"].get("tags", []) for c in cells)
        assert model["content"]["metadata"]["jupytext"]["text_representation"]["format_name"] == "percent"
        proc = lab.proc
    # stopped, nothing of its process group left
    assert proc.poll() is not None and not _group_alive(proc.pid)

"""``sixdpose fetch-weights`` against a local HTTP server (with Range support) and a temporary torch hub cache:
download, checksum, resume, restart, errors, and the segmentation stage loading the fetched file. No real
network."""

from __future__ import annotations

import hashlib
import http.server
import io
import random
import re
import socket
import threading
from pathlib import Path

import pytest

from sixdpose.cli import main

BODY = random.Random(0).randbytes(300_000)
DIGEST = hashlib.sha256(BODY).hexdigest()


class _Server:
    """A threaded HTTP server of ``files`` (path -> bytes) that answers ``Range: bytes=N-`` with 206 (or
    ignores it, per path), can cut a response short, and records every request's path and Range header."""

    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}
        self.ignore_range: set[str] = set()
        self.cut: set[str] = set()  # send Content-Length of the whole body, then half of it, then close
        self.requests: list[tuple[str, str | None]] = []
        self.sent = 0
        server = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802
                rng = self.headers.get("Range")
                server.requests.append((self.path, rng))
                body = server.files.get(self.path)
                if body is None:
                    self.send_error(404)
                    return
                m = re.fullmatch(r"bytes=(\d+)-", rng or "")
                start = int(m.group(1)) if m and self.path not in server.ignore_range else None
                if start is not None and start >= len(body):
                    self.send_response(416)
                    self.send_header("Content-Range", f"bytes */{len(body)}")
                    self.send_header("Content-Length", "0")
                    self.end_headers()
                    return
                if start is not None:
                    self.send_response(206)
                    self.send_header("Content-Range", f"bytes {start}-{len(body) - 1}/{len(body)}")
                    part = body[start:]
                else:
                    self.send_response(200)
                    part = body
                self.send_header("Content-Length", str(len(part)))
                self.end_headers()
                if self.path in server.cut:
                    part = part[: len(part) // 2]
                # counted before the write: the client may have read the whole body and the test asserted
                # on `sent` before this thread runs again after the write
                server.sent += len(part)
                self.wfile.write(part)
                self.wfile.flush()
                self.close_connection = True

            def log_message(self, *a):
                pass

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"


@pytest.fixture
def server():
    s = _Server()
    s.files["/resnet50-weights.pth"] = BODY
    t = threading.Thread(target=s.httpd.serve_forever, daemon=True)
    t.start()
    yield s
    s.httpd.shutdown()
    s.httpd.server_close()


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    """The resnet50 weights file of a temporary torch hub cache ($TORCH_HOME), also checked to be the file
    the segmentation stage looks for."""
    from sixdpose.assets.weights import cached_weights_path
    from sixdpose.segmentation import model

    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch"))
    path = cached_weights_path("resnet50")
    assert path.is_relative_to(tmp_path / "torch" / "hub" / "checkpoints")
    assert Path(model.cached_weights_path("resnet50")) == path
    return path


def _fetch(capsys, *args: str) -> tuple[int, str, list[str]]:
    rc = main(["fetch-weights", "--no-progress", "--timeout", "20", *args])
    out, err = capsys.readouterr()
    return rc, out, err.strip().splitlines()


def test_torchvision_url_and_hash_prefix(tmp_path, monkeypatch):
    """Without --url / --sha256: torchvision's own URL, and the hash prefix of its file name (as torch.hub)."""
    import torch.hub
    from torchvision.models import ResNet50_Weights

    from sixdpose.assets.weights import weights_file

    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    w = weights_file()
    url = ResNet50_Weights.IMAGENET1K_V1.url
    assert w.url == url and w.path == tmp_path / "hub" / "checkpoints" / url.rsplit("/", 1)[1]
    assert w.sha256 == torch.hub.HASH_REGEX.search(w.path.name).group(1) and len(w.sha256) >= 8
    assert w.part.name == w.path.name + ".part"


def test_good_file_lands_in_the_cache_then_short_circuits(server, cache, capsys):
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", DIGEST[:8])
    assert rc == 0, err
    assert cache.read_bytes() == BODY and "downloaded, checksum ok" in out
    assert sorted(p.name for p in cache.parent.iterdir()) == [cache.name]  # no .part left
    assert server.requests == [("/resnet50-weights.pth", None)]
    # again: nothing downloaded
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", DIGEST)
    assert rc == 0 and "already present, checksum ok" in out and len(server.requests) == 1


def test_progress_bar(server, cache, capsys):
    rc = main(["fetch-weights", "--url", server.url + "/resnet50-weights.pth", "--sha256", DIGEST])
    err = capsys.readouterr().err
    assert rc == 0 and cache.name in err and "%" in err  # tqdm's bar on stderr


def test_bad_checksum_leaves_nothing(server, cache, capsys):
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", "0" * 64)
    assert rc != 0 and len(err) == 1
    assert "checksum mismatch" in err[0] and str(cache) in err[0] and server.url in err[0]
    assert list(cache.parent.iterdir()) == []


def test_a_present_file_with_a_bad_checksum_is_replaced(server, cache, capsys):
    cache.parent.mkdir(parents=True)
    cache.write_bytes(b"not the weights")
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", DIGEST)
    assert rc == 0 and cache.read_bytes() == BODY


def test_server_down_is_one_line_naming_the_url(cache, capsys):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"http://127.0.0.1:{port}/resnet50-weights.pth"
    rc, out, err = _fetch(capsys, "--url", url, "--sha256", DIGEST)
    assert rc != 0 and len(err) == 1 and f"cannot reach {url}" in err[0] and "Traceback" not in err[0]
    assert not cache.parent.exists() or list(cache.parent.iterdir()) == []


def test_http_error_and_bad_sha256_are_one_line(server, cache, capsys):
    rc, out, err = _fetch(capsys, "--url", server.url + "/missing.pth", "--sha256", DIGEST)
    assert rc != 0 and len(err) == 1 and "HTTP 404" in err[0] and "/missing.pth" in err[0]
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", "xyz")
    assert rc == 2 and len(err) == 1 and "hexadecimal" in err[0] and server.requests[-1][0] == "/missing.pth"


def test_resume_a_part_file_with_range(server, cache, capsys):
    half = len(BODY) // 2
    cache.parent.mkdir(parents=True)
    Path(str(cache) + ".part").write_bytes(BODY[:half])
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", DIGEST)
    assert rc == 0, err
    assert server.requests == [("/resnet50-weights.pth", f"bytes={half}-")] and server.sent == len(BODY) - half
    assert cache.read_bytes() == BODY and sorted(p.name for p in cache.parent.iterdir()) == [cache.name]


def test_a_complete_part_file_is_checked_and_moved(server, cache, capsys):
    cache.parent.mkdir(parents=True)
    Path(str(cache) + ".part").write_bytes(BODY)
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", DIGEST)
    assert rc == 0 and server.sent == 0 and cache.read_bytes() == BODY  # 416: nothing left to send


def test_server_ignoring_range_restarts(server, cache, capsys):
    server.ignore_range.add("/resnet50-weights.pth")
    cache.parent.mkdir(parents=True)
    Path(str(cache) + ".part").write_bytes(b"\0" * 1000)  # would corrupt the file if appended to
    rc, out, err = _fetch(capsys, "--url", server.url + "/resnet50-weights.pth", "--sha256", DIGEST)
    assert rc == 0, err
    assert server.requests == [("/resnet50-weights.pth", "bytes=1000-")] and server.sent == len(BODY)
    assert cache.read_bytes() == BODY


def test_an_interrupted_download_resumes(server, cache, capsys):
    url = server.url + "/resnet50-weights.pth"
    server.cut.add("/resnet50-weights.pth")
    rc, out, err = _fetch(capsys, "--url", url, "--sha256", DIGEST)
    part = Path(str(cache) + ".part")
    assert rc != 0 and len(err) == 1 and "run again to resume" in err[0] and url in err[0]
    assert not cache.exists() and part.read_bytes() == BODY[: len(BODY) // 2]
    server.cut.clear()
    rc, out, err = _fetch(capsys, "--url", url, "--sha256", DIGEST)
    assert rc == 0, err
    assert server.requests[-1] == ("/resnet50-weights.pth", f"bytes={len(BODY) // 2}-")
    assert cache.read_bytes() == BODY and not part.exists()


def test_the_segmentation_stage_loads_the_fetched_file(server, tmp_path, monkeypatch, capsys):
    """A fetched file is the one train-seg's model builder then initialises its backbone from."""
    import torch
    import torchvision

    from sixdpose.segmentation.config import profile_config
    from sixdpose.segmentation.model import build_model

    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch"))
    ref = torchvision.models.resnet18().state_dict()
    buf = io.BytesIO()
    torch.save(ref, buf)
    server.files["/resnet18-mirror.pth"] = buf.getvalue()
    digest = hashlib.sha256(buf.getvalue()).hexdigest()
    rc, out, err = _fetch(capsys, "--backbone", "resnet18", "--url", server.url + "/resnet18-mirror.pth",
                          "--sha256", digest)
    assert rc == 0, err
    model, init = build_model(profile_config("smoke", pretrained=True), 3)
    assert init == "imagenet"
    assert torch.equal(model.backbone.body.state_dict()["layer4.1.conv2.weight"], ref["layer4.1.conv2.weight"])

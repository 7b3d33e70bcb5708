"""The preview against hostile and careless input (issue 38): an edit never changes which files are
read (none outside the served document is opened, and no answer holds a byte of one), a body or
message of the wrong shape is a 400 or a JSON error with one line and no traceback on the server's
console, the command line refuses a port or host it cannot listen on before the server starts,
a server bound beyond loopback admits its token whatever the Host, saved settings are checked as
frames are, and a view's fields have their JSON types."""

from __future__ import annotations

import errno
import http.client
import json
import os
import socket
import subprocess
import sys
import uuid
from pathlib import Path
from urllib.parse import urlsplit

import pytest

pytest.importorskip("starlette", reason="the preview extra: pip install 'xrayraster[preview]'")

from starlette.testclient import TestClient  # noqa: E402

from xrayraster.core.errors import ConfigError  # noqa: E402
from xrayraster.preview.document import Document, View  # noqa: E402
from xrayraster.preview.notebook import free_port  # noqa: E402
from xrayraster.preview.server import Background, make_app  # noqa: E402
from xrayraster.preview.session import Preview  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TIMEOUT_S = 60

# -- who opens what: an audit hook, added once (hooks cannot be removed), watching while WATCHED is filled

WATCHED: set[str] = set()  # substrings of paths no one may open
OPENED: list[str] = []  # the watched paths opened


def _audit(event: str, args: tuple) -> None:
    if event == "open" and WATCHED and args and isinstance(args[0], (str, bytes, os.PathLike)):
        name = os.fsdecode(os.fspath(args[0]))
        if any(token in name for token in WATCHED):
            OPENED.append(name)


sys.addaudithook(_audit)


@pytest.fixture
def scene_file(tmp_path) -> Path:
    """The bracket-and-ball example in a folder of its own, its detector small (64 × 80), its mesh
    named by absolute path."""
    text = (EXAMPLES / "bracket_and_ball.toml").read_text()
    text = text.replace("detector_shape = [256, 320]", "detector_shape = [64, 80]").replace(
        "pixel_size = 0.15 ", "pixel_size = 0.6  ").replace('mesh = "meshes/bracket.stl"',
                                                           f'mesh = "{EXAMPLES / "meshes" / "bracket.stl"}"')
    path = tmp_path / "served" / "scene.toml"
    path.parent.mkdir()
    path.write_text(text)
    return path


@pytest.fixture
def scan_file(scene_file) -> Path:
    """The same scene as a scan file with a mount (a scan file's other mesh key)."""
    path = scene_file.with_name("scan.toml")
    path.write_text(scene_file.read_text() + '\n[scan]\nnoise = false\n\n[[mount]]\nname = "stand"\n'
                    'mesh = { box = [4.0, 4.0, 2.0] }\nmaterial = "aluminium"\ntranslate = [0.0, 0.0, -8.0]\n')
    return path


class Secrets:
    """Files outside the served folder, each with a content marker no path holds: a text file
    (a spectrum file's place) and a closed mesh (an object's), named absolutely, by ``../`` from the
    served folder, and through symbolic links inside it."""

    def __init__(self, tmp_path: Path, served: Path):
        self.token, self.marker = f"xr-secret-{uuid.uuid4().hex}", f"MARKER{uuid.uuid4().hex}"
        outside = tmp_path / "outside"
        outside.mkdir()
        text, mesh = outside / f"{self.token}.txt", outside / f"{self.token}.stl"
        text.write_text(f"{self.marker} first line of a private file\n10 1\n")
        mesh.write_text(f"solid {self.marker}\n" + "".join(
            f"facet normal 0 0 0\nouter loop\n{''.join(f'vertex {x} {y} {z}' + chr(10) for x, y, z in face)}"
            "endloop\nendfacet\n" for face in _TETRAHEDRON) + f"endsolid {self.marker}\n")
        self.paths = {}
        for kind, target in (("text", text), ("mesh", mesh)):
            link = served / f"{self.token}-link{target.suffix}"
            link.symlink_to(target)
            self.paths[kind] = [str(target), f"../outside/{target.name}", link.name]
        self.missing = str(outside / "absent.txt")  # a path that does not exist: refused the same


_TETRAHEDRON = [((0, 0, 0), (0, 9, 0), (9, 0, 0)), ((0, 0, 0), (9, 0, 0), (0, 0, 9)),
                ((0, 0, 0), (0, 0, 9), (0, 9, 0)), ((9, 0, 0), (0, 9, 0), (0, 0, 9))]


@pytest.fixture
def secrets(tmp_path, scene_file):
    found = Secrets(tmp_path, scene_file.parent)
    WATCHED.add(found.token)
    OPENED.clear()
    yield found
    WATCHED.clear()


def file_edits(kind: str, path: str) -> list[dict]:
    """Edits that would make a scene or scan file read ``path``: the key itself, and each table or
    array above it replaced whole."""
    object_ = {"mesh": path, "material": "aluminium"}
    if kind == "text":
        return [{"source.spectrum_file": path}, {"source": {"spectrum_file": path}}]
    return [{"objects.0.mesh": path}, {"objects.00.mesh": path}, {"objects.0": object_}, {"objects": [object_]},
            {"mount.0.mesh": path}, {"mount": [object_]}]


def client(path: Path, **options) -> TestClient:
    preview = Preview(Document.open(path), threads=1)
    app = make_app(preview, host="127.0.0.1", port=8000, **options)
    return TestClient(app, base_url="http://127.0.0.1:8000", raise_server_exceptions=False)


def refusals(c: TestClient, edits: dict):
    """What each way in answers ``edits``: (the way, the HTTP status or None, the answer's bytes)."""
    body = {"edits": edits, "view": {}}
    for way in ("/save/settings.toml", "/save/view.tif", "/save/view.png", "/slice"):
        answer = c.post(way, json=body)
        yield way, answer.status_code, answer.content
    with c.websocket_connect("ws://127.0.0.1:8000/frames") as ws:
        ws.receive_json()  # hello
        ws.send_text(json.dumps({"id": 7, **body}))
        yield "websocket", None, ws.receive_text().encode()


def test_an_edit_never_reads_a_file_the_document_does_not_name(secrets, scene_file, scan_file):
    for served in (scene_file, scan_file):
        with client(served) as c:
            for kind, paths in secrets.paths.items():
                for path in paths:
                    for edits in file_edits(kind, path):
                        if "mount" in next(iter(edits)) and served is scene_file:
                            continue  # a scene file has no mount
                        (key,) = edits
                        missing = {key: json.loads(json.dumps(edits[key]).replace(json.dumps(path)[1:-1],
                                                                                  secrets.missing))}
                        for (way, status, body), (_, _, elsewhere) in zip(refusals(c, edits), refusals(c, missing)):
                            what = f"{served.name} {way} {edits}"
                            assert secrets.marker.encode() not in body, what
                            assert not OPENED, f"{what} opened {OPENED}"
                            assert status in (None, 400), what
                            error = json.loads(body)["error"]
                            assert f"'{key}'" in error and "\n" not in error, what
                            # Whether a path exists is not told: a missing one gets the same answer.
                            assert json.loads(elsewhere)["error"] == error, what
    (scene_file.parent / secrets.paths["text"][2]).read_bytes()  # through the link
    assert OPENED, "the audit hook saw no open: it checks nothing"


def test_the_documents_own_files_still_load_and_values_still_change(scene_file):
    """The rule fixes which files are read, not the values: a key below an object still edits."""
    with client(scene_file) as c:
        saved = c.post("/save/settings.toml", json={"edits": {"objects.0.priority": 3.0, "objects.1.mesh.sphere": 2.0},
                                                    "view": {}})
        assert saved.status_code == 200, saved.text
        assert str(EXAMPLES / "meshes" / "bracket.stl") in saved.text and "sphere = 2.0" in saved.text


@pytest.mark.parametrize("body", ["[1, 2]", '"x"', "null", "3", "{", "\xff"])
@pytest.mark.parametrize("way", ["/save/settings.toml", "/save/view.png", "/slice"])
def test_a_body_that_is_not_a_json_object_is_a_one_line_400(scene_file, body, way):
    with client(scene_file) as c:
        answer = c.post(way, content=body.encode("latin-1"))
    assert answer.status_code == 400, answer.text
    error = answer.json()["error"]
    assert error.startswith("a request must be") and "\n" not in error


@pytest.mark.parametrize("edits", [{"source.kvp": float("nan")}, {"source.kvp": -5},
                                   {"geometry.detector_shape": [-5, 1e8]}])
def test_saved_settings_are_checked_as_frames_are(scene_file, edits):
    (key,) = edits
    with client(scene_file) as c:
        answer = c.post("/save/settings.toml", content=json.dumps({"edits": edits, "view": {}}))
    assert answer.status_code == 400, answer.text
    assert key.split(".")[1] in answer.json()["error"]


@pytest.mark.parametrize("view, field", [({"noise": "yes"}, "noise"), ({"noise": 1}, "noise"),
                                         ({"noise": None}, "noise"), ({"angle_deg": True}, "angle_deg"),
                                         ({"output": 3}, "output"), ({"output": ["lineint"]}, "output"),
                                         ({"seed": 1.5}, "seed"), ({"material": "0"}, "material"),
                                         ({"angle_deg": "12"}, "angle_deg")])
def test_a_views_fields_have_their_json_types(view, field):
    with pytest.raises(ConfigError, match=f"view: {field} must be") as error:
        View.from_dict(view)
    assert "\n" not in str(error.value)


def test_a_views_unknown_fields_are_named_with_the_ones_it_takes():
    with pytest.raises(ConfigError, match=r"^view: unknown key\(s\) tilt, zoom; allowed: angle_deg, material, "
                                          r"noise, output, seed$"):
        View.from_dict({"zoom": 2, "tilt": 1.0, "seed": 3})


def test_a_binary_message_is_answered_and_the_server_keeps_serving(scene_file, gl):
    from websockets.sync.client import connect

    with Background(scene_file, port=free_port(), threads=1) as server, \
            connect(server.url.replace("http", "ws", 1) + "frames", open_timeout=TIMEOUT_S) as ws:
        view = json.loads(ws.recv(timeout=TIMEOUT_S))["view"]
        ws.send(b"\x00\x01binary")
        answer = json.loads(ws.recv(timeout=TIMEOUT_S))
        assert answer["id"] is None and "text" in answer["error"]
        ws.send(json.dumps({"id": 3, "edits": {}, "view": view}))
        assert len(ws.recv(timeout=TIMEOUT_S)) > 64 * 80  # a frame: the server kept serving


# -- a real server: its console, its address ---------------------------------------------------


def _post(port: int, path: str, body: bytes, host: str | None = None) -> tuple[int, bytes]:
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=TIMEOUT_S)
    try:
        connection.request("POST" if body is not None else "GET", path, body=body,
                           headers={"Host": host} if host else {})
        answer = connection.getresponse()
        return answer.status, answer.read()
    finally:
        connection.close()


def test_refusals_leave_no_traceback_on_the_servers_console(scene_file, secrets, capfd, caplog):
    from websockets.sync.client import connect

    with Background(scene_file, port=free_port(), threads=1) as server:
        port = urlsplit(server.url).port
        for body in (b"[1,2]", b'"x"', b"null", b"{", b'{"edits": {"source.kvp": NaN}, "view": {}}',
                     json.dumps({"edits": {"source.spectrum_file": secrets.paths["text"][0]}, "view": {}}).encode(),
                     json.dumps({"edits": {}, "view": {"noise": "yes"}}).encode()):
            for way in ("/save/settings.toml", "/save/view.png", "/slice"):
                status, answer = _post(port, way, body)
                assert status == 400 and secrets.marker.encode() not in answer, (way, body, answer)
        with connect(f"ws://127.0.0.1:{port}/frames", open_timeout=TIMEOUT_S) as ws:
            json.loads(ws.recv(timeout=TIMEOUT_S))  # hello
            for message in (b"\x00binary", "[1, 2]", "null", json.dumps({"id": 1, "edits": [], "view": {}})):
                ws.send(message)
                assert "error" in json.loads(ws.recv(timeout=TIMEOUT_S)), message
    console = capfd.readouterr().err
    assert "Traceback" not in console and "Exception" not in console, console
    assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL")]
    assert not OPENED


def test_bound_beyond_loopback_the_token_admits_any_host_and_the_address_is_usable(scene_file):
    from xrayraster.core.errors import XrayrasterWarning

    with pytest.warns(XrayrasterWarning, match="beyond this machine's loopback"):
        server = Background(scene_file, host="0.0.0.0", port=free_port(), threads=1)
    with server:
        url = urlsplit(server.url)
        token = dict(part.split("=", 1) for part in url.query.split("&"))["token"]
        assert url.hostname not in ("0.0.0.0", "::") and socket.getaddrinfo(url.hostname, url.port)
        named = f"preview-host.example:{url.port}"  # a name of this machine another one might use
        assert _post(url.port, f"/?token={token}", None, host=named)[0] == 200
        assert _post(url.port, "/", None, host=named)[0] == 403
        assert _post(url.port, "/?token=wrong", None, host=named)[0] == 403
    with client(scene_file) as c:  # on loopback, the Host check stays (DNS rebinding)
        assert c.get("/", headers={"host": "preview-host.example:8000"}).status_code == 403


# -- the command line: an address it cannot listen on, refused before the server starts ----------


def _preview(scene_file: Path, *options: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "xrayraster", "preview", str(scene_file), *options],
                          capture_output=True, text=True, timeout=TIMEOUT_S)


def test_a_port_out_of_range_is_refused_by_the_options(scene_file):
    done = _preview(scene_file, "--port", "70000")
    assert done.returncode == 2, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert "--port" in last and "65535" in last and "Traceback" not in done.stderr


def test_a_port_in_use_is_one_line_and_status_2(scene_file):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        done = _preview(scene_file, "--port", str(taken.getsockname()[1]))
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "--port" in done.stderr, done.stderr


def test_a_host_that_is_not_this_machines_is_one_line_and_status_2(scene_file):
    host = "10.99.99.99"
    with socket.socket() as probe:
        try:
            probe.bind((host, 0))
            pytest.skip(f"{host} is an address of this machine")
        except OSError as exc:
            assert exc.errno == errno.EADDRNOTAVAIL
    done = _preview(scene_file, "--host", host, "--port", str(free_port()))
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "--host" in done.stderr, done.stderr


def test_a_dataset_file_is_named_as_one_not_as_unknown_keys(capsys):
    """`preview DATASET.toml` said "unknown key(s) base, dataset": it says what the file is instead."""
    from xrayraster import cli

    assert cli.main(["preview", str(EXAMPLES / "dataset_small.toml"), "--port", str(free_port())]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "dataset_small.toml is a dataset file" in line and "xrayraster build" in line and "unknown" not in line


def test_from_python_a_port_in_use_is_a_config_error_naming_it(scene_file):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError, match=f"^port {port}: already in use on 127.0.0.1"):
            Background(scene_file, port=port)

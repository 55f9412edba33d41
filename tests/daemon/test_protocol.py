"""orccadctl and the protocol against a running orccadd: commands, refusals, malformed requests, roles."""

from __future__ import annotations

import contextlib
import json
import os
import pwd
import socket
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from orccadd.ctl.client import Client
from orccadd.wire.schema import PROTOCOL_VERSION
from tests.daemon.conftest import ROOT, Daemon, start_daemon

DEMO_TEXT = (ROOT / "configs/missions/demo.mission").read_text()
DEMO = str(ROOT / "configs/missions/demo.mission")
UNHANDLED = str(ROOT / "tests/automaton/missions/unhandled_t3.mission")

MALFORMED: list[bytes] = [
    b"not json\n",
    b"{\n",
    b"[]\n",
    b'"status"\n',
    b"42\n",
    b"null\n",
    b"{}\n",
    b'{"cmd": 7}\n',
    b'{"cmd": null}\n',
    b'{"cmd": "fly"}\n',
    b'{"cmd": "status", "args": []}\n',
    b'{"cmd": "status", "args": "x"}\n',
    b'{"cmd": "status", "extra": 1}\n',
    b'{"cmd": "load"}\n',
    b'{"cmd": "load", "args": {"path": 5}}\n',
    b'{"cmd": "tune", "args": {"path": "Hold.pd.kp"}}\n',
    b'{"cmd": "tune", "args": {"path": "Hold.pd.kp", "value": "high"}}\n',
    b'{"cmd": "monitor", "args": {"rate_hz": true}}\n',
    b'{"cmd": "start", "args": {"procedure": "x", "now": 1}}\n',
    b"\xff\xfe\xfd\n",
    b'{"cmd": "monitor", "args": {"rate_hz": 1e9, "count": 1}}\n',
    b'{"cmd": "monitor", "args": {"signals": ["zz"], "count": 1}}\n',
    b'{"cmd": "events", "args": {"last": -5}}\n',
    b'{"cmd": "log", "args": {"action": "explode"}}\n',
]


def test_malformed_requests_get_an_error_and_change_nothing(daemon: Daemon) -> None:
    before = daemon.status()
    with daemon.client() as c:
        for raw in MALFORMED:
            r = c.send_raw(raw)
            assert r["ok"] is False and r["error"], raw
        assert c.call("ping")["pong"]  # same connection still served
    with daemon.client() as c:  # an oversized line: error, then the connection is closed
        r = c.send_raw(b'{"cmd": "status", "args": {"x": "' + b"a" * 70_000 + b'"}}\n')
        assert r["ok"] is False and "longer than" in r["error"]
    after = daemon.status()
    assert after["state"] == before["state"] == "idle" and not after["faulted"]
    assert int(after["ticks"]) > int(before["ticks"])  # the loop carried on
    ev = daemon.call("events")
    assert isinstance(ev, dict)
    assert not [e for e in ev["events"] if e["kind"] == "command"], ev  # no request was acted on


def test_refused_mission_shows_the_counterexample(daemon: Daemon) -> None:
    p = daemon.ctl("load", UNHANDLED)
    assert p.returncode == 1
    assert "counterexample" in p.stderr and "safety" in p.stderr
    assert daemon.status()["state"] == "idle"


def test_params_and_tune(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    params = daemon.call("params", task="Reach")
    assert isinstance(params, dict)
    kp = next(p for p in params["params"]["Reach"] if p["name"] == "ct.kp")
    assert kp["tunable"] and kp["unit"]
    ok = daemon.ctl("tune", "Reach.ct.kp", "[500, 500, 500, 500, 500, 500]")
    assert ok.returncode == 0, ok.stderr
    before = int(daemon.status()["ticks"])  # type: ignore[arg-type]
    reply = daemon.call("tune", path="Reach.ct.kp[2]", value=600)  # one joint's: the elbow's
    after = int(daemon.status()["ticks"])  # type: ignore[arg-type]
    # acknowledged once the control thread applied it, with that tick's (telemetry record) number
    assert isinstance(reply, dict) and reply["previous"] == 500.0 and reply["tuned"] == "Reach.ct.kp[2]"
    assert reply["unit"] == kp["unit"]  # its unit in the same reply: no second request
    assert reply["task_active"] is False  # loaded, not started: set now, acting when Reach runs
    assert before <= reply["applied_at_tick"] <= after + 1, (before, reply, after)
    applied = daemon.call("tune", path="Reach.ct.kp[5]", value=400)
    # the trace (and every log) says which parameter, before → after, and the tick that applied it
    tunes = [e["tune"] for e in daemon.call("events", last=10)["events"] if e.get("tune")]  # type: ignore[index]
    assert tunes[-2:] == [
        {"path": "Reach.ct.kp[2]", "old": [500.0], "new": [600.0], "n": 1, "tick": reply["applied_at_tick"]},
        {
            "path": "Reach.ct.kp[5]",
            "old": [500.0],
            "new": [400.0],
            "n": 1,
            "tick": applied["applied_at_tick"],
        },  # type: ignore[index]
    ]
    params = daemon.call("params", task="Reach")
    kp = next(p for p in params["params"]["Reach"] if p["name"] == "ct.kp")["value"]
    assert kp == [500.0, 500.0, 600.0, 500.0, 500.0, 400.0]
    for path, value, why in [
        ("Reach.ct.kp", "500", "(=500): kp has 6 values, one per joint: give a list of 6, or one joint's as"),
        ("Reach.ct.kp[6]", "500", "ct.kp has indices 0 to 5"),
        ("Reach.ct.kp[x]", "500", "an element is named PARAM[i]"),
        ("Reach.ct.kp[1]", "[1, 2]", "must be one number"),
        ("Reach.traj.speed_scale[0]", "1", "no index: it is one number"),
        ("Reach.ct.kp[0]", "-3", "must be in"),
        ("Reach.ct.kp", "[-3, 1, 1, 1, 1, 1]", "must be in"),
        ("Reach.ct.nope", "1", "no parameter"),
        ("Nobody.ct.kp", "1", "no task"),
        ("Reach.kp", "1", "TASK.MODULE.PARAM"),
    ]:
        p = daemon.ctl("tune", path, value)
        assert p.returncode == 1 and why in p.stderr, (path, p.stderr)
    ev = daemon.call("events")
    assert isinstance(ev, dict)
    assert [e["command"] for e in ev["events"] if e["kind"] == "command"].count("tune") == 3  # the served
    assert (
        kp
        == next(p for p in daemon.call("params", task="Reach")["params"]["Reach"] if p["name"] == "ct.kp")[
            "value"
        ]
    )  # nothing refused changed anything


def test_two_clients_monitor_while_another_commands(daemon: Daemon) -> None:
    samples: list[dict[str, object]] = []

    def watch() -> None:
        with daemon.client() as c:
            samples.extend(c.stream("monitor", signals=["q", "wake_us"], rate_hz=50.0, count=60))

    t = threading.Thread(target=watch)
    t.start()
    daemon.call("load", path=DEMO)
    daemon.call("start")
    t.join(timeout=30)
    assert not t.is_alive()
    assert samples[0]["signals"][0] == "t_s" and len(samples) == 61  # type: ignore[index]
    times = [s["t_s"] for s in samples[1:]]
    assert times == sorted(times)
    daemon.call("abort")


def test_monitor_and_log_through_orccadctl(daemon: Daemon, tmp_path: Path) -> None:
    out = tmp_path / "run.csv"
    assert daemon.ctl("log", "start", "q", "tau", "--name", "run.csv").returncode == 0
    p = daemon.ctl("monitor", "q.0", "compute_us", "--rate", "20", "--count", "5", "--json")
    assert p.returncode == 0, p.stderr
    lines = [json.loads(x) for x in p.stdout.splitlines()]
    assert lines[0]["signals"] == ["t_s", "q.shoulder_pan_joint", "compute_us"] and len(lines) == 6
    stop = daemon.ctl("log", "stop", "-o", str(out), "--json")
    info = json.loads(stop.stdout)["result"]
    assert info["rows"] > 100 and info["lost"] == 0
    header = next(x for x in out.read_text().splitlines() if not x.startswith("#")).split(",")
    assert header[0] == "time_s" and len(header) == 13
    copied = tmp_path / "run.mcap"  # the MCAP beside the CSV comes along, read by mcap's reader
    with copied.open("rb") as f:
        topics = {ch.topic for ch in make_reader(f).get_summary().channels.values()}  # type: ignore[union-attr]
    assert {"/q", "/tau", "/joint_states", "/events"} <= topics
    png = tmp_path / "run.png"
    assert daemon.ctl("plot", str(out), "-o", str(png)).returncode == 0
    assert png.stat().st_size > 1000


def test_log_stop_copies_only_to_a_path_on_its_own_command_line(daemon: Daemon, tmp_path: Path) -> None:
    """The copy goes where the user stopping the log says, never where the one who started it
    said (a control user naming root's file, root's `log stop` overwriting it), never through a
    link or into a FIFO."""
    victim = tmp_path / "victim.csv"
    victim.write_text("root's file\n")
    r = daemon.reply("log", action="start", name="a.csv", dest=str(victim))
    assert not r["ok"] and "dest" in str(r["error"]), r  # the daemon stores no destination
    p = daemon.ctl("log", "start", "q", "-o", str(victim))
    assert p.returncode == 2 and "log stop -o" in p.stderr, p.stderr
    assert daemon.ctl("log", "start", "q", "--name", "b.csv").returncode == 0
    link = tmp_path / "planted.csv"
    link.symlink_to(victim)
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    for dest in (link, fifo):
        p = daemon.ctl("log", "stop", "-o", str(dest), timeout_s=20)
        assert p.returncode == 2 and "not copied" in p.stderr, (dest, p.returncode, p.stdout, p.stderr)
        assert daemon.ctl("log", "start", "q", "--name", f"{dest.stem}.csv").returncode == 0
    assert victim.read_text() == "root's file\n" and link.is_symlink()
    assert not (tmp_path / "planted.mcap").exists()
    p = daemon.ctl("log", "stop")  # no -o: nothing copied anywhere, the log stays in the log directory
    assert p.returncode == 0 and "log stop -o" not in p.stdout and "rows" in p.stdout, p.stdout


def _as_nobody(sock: str, cmd: str) -> dict[str, object]:
    """One request from a forked child running as user nobody (its peer credentials)."""
    reply = _as_nobody_many(sock, 1, cmd)[0]
    assert "child_error" not in reply, reply
    return reply


def _reachable_by_nobody(tmp_path: Path) -> None:
    """Let user nobody walk to a socket under `tmp_path` (pytest's directories are 0700)."""
    tmp_path.chmod(0o755)
    for p in tmp_path.parents:
        if str(p).startswith("/tmp/") and p != Path("/tmp"):
            p.chmod(p.stat().st_mode | 0o005)


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run a client as another user")
def test_unauthorised_peer_is_refused(tmp_path: Path) -> None:
    _reachable_by_nobody(tmp_path)
    # nobody may reach the socket (group nogroup) but holds no role at first
    nogroup = "nogroup"
    d = start_daemon(tmp_path, daemon_cfg=f'socket_group = "{nogroup}"')
    try:
        mode = (Path(d.socket).stat().st_mode & 0o777, Path(d.socket).parent.stat().st_mode & 0o777)
        assert mode == (0o660, 0o750)
        r = _as_nobody(d.socket, "status")
        assert r["ok"] is False and "not authorised" in str(r["error"])
        assert d.status()["state"] == "idle"
    finally:
        d.stop()
    d = start_daemon(tmp_path, daemon_cfg=f'socket_group = "{nogroup}"\nread_groups = ["{nogroup}"]')
    try:
        assert _as_nobody(d.socket, "status")["ok"] is True  # read-only role
        r = _as_nobody(d.socket, "abort")
        assert r["ok"] is False and "control role" in str(r["error"])
        assert not d.status()["faulted"]
        ev = d.call("events")
        assert isinstance(ev, dict)
        assert "abort" not in [e["command"] for e in ev["events"] if e["kind"] == "command"], ev
    finally:
        d.stop()


def test_too_many_clients(daemon: Daemon) -> None:
    first = daemon.call("ping")
    assert isinstance(first, dict)
    assert first["pong"] is True and first["protocol_version"] == PROTOCOL_VERSION
    assert isinstance(first["pid"], int) and first["pid"] != daemon.proc.pid  # the command daemon's own
    socks = []
    try:
        for _ in range(40):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(daemon.socket)
            socks.append(s)
        with Client(daemon.socket) as c:
            r = c.reply("ping")
        assert r["ok"] is False and "too many clients" in str(r["error"])
    finally:
        for s in socks:
            s.close()
    # served again once they leave, by the same command daemon (not a respawned one)
    assert daemon.call("ping") == first


def test_load_reads_only_the_configured_mission_directories(daemon: Daemon, tmp_path: Path) -> None:
    secret = tmp_path.parent / "secret.mission"  # outside every mission directory
    secret.write_text("root-only line\n")
    link = tmp_path / "link.mission"  # inside one, pointing outside
    link.symlink_to(secret)
    for path in (str(secret), str(link), "/etc/shadow", "/" + "x" * 300):
        r = daemon.reply("load", path=path)
        assert not r["ok"] and "mission files are loaded from" in r["error"], r
        assert "root-only" not in r["error"]
    assert daemon.call("load", path=DEMO)["mission"]["name"] == "PickDemo"  # type: ignore[index]


def test_a_mission_is_named_as_installed(daemon: Daemon) -> None:
    """`orccadctl load demo`: the first demo.mission of the daemon's mission directories (from a
    wheel the user knows the name, not the path under share/)."""
    r = daemon.ctl("load", "demo")
    assert r.returncode == 0, r.stderr
    assert daemon.status()["mission"] == "PickDemo"
    r = daemon.ctl("load", "nosuch")
    assert r.returncode == 1 and "mission files are loaded from" in r.stderr, r.stderr


def test_a_task_file_outside_the_task_and_mission_directories_is_not_read(
    daemon: Daemon, tmp_path: Path
) -> None:
    """A mission (in a mission directory) naming a task file anywhere else: refused in the same
    words whether that file exists or not, without a key of it quoted."""
    outside = tmp_path.parent / "elsewhere"
    outside.mkdir(exist_ok=True)
    toml = outside / "keys.toml"
    toml.write_text('secret_key_x = "root-only"\n[table_y]\nz = 1\n')
    errors = []
    for target in (toml, outside / "absent.toml", Path("/etc/passwd")):
        m = tmp_path / f"m{len(errors)}.mission"
        m.write_text(f'mission M\nresource arm\ntask T on arm from "{target}"\n  post\nend\n'
                     "main procedure P\n  T\nend\n")  # fmt: skip
        r = daemon.reply("load", path=str(m))
        assert not r["ok"], r
        assert "task files are loaded from" in r["error"] and "daemon.task_dirs" in r["error"], r
        assert "secret_key" not in r["error"] and "table_y" not in r["error"] and "root:" not in r["error"]
        errors.append(str(r["error"]).replace(str(target), "FILE"))
    assert errors[0] == errors[1].replace("m1.mission", "m0.mission"), errors


def _long_mission(path: Path, motions: int) -> Path:
    """The demo's tasks in a sequence of `motions` (each state of the automaton as long as the
    rest of the sequence: compiling it takes seconds and memory)."""
    head = DEMO_TEXT.split("main procedure")[0].replace('"../tasks/', f'"{ROOT}/configs/tasks/')
    body = ";\n".join("      Home" if i % 2 == 0 else "      Reach" for i in range(motions))
    path.write_text(
        f"{head}main procedure Long\n  handle\n    do\n{body}\n    until Stop\n  on fatal do safe end\nend\n"
        "safe procedure Ack\n  await Stop\nend\n"
    )
    return path


def test_a_load_past_its_time_or_memory_is_refused_saying_which_and_the_next_one_works(
    tmp_path: Path,
) -> None:
    """A mission too large for the daemon's limits is refused with the limit named, in the real-time
    process's own words (before: both sides timed out at 600 s and its message was lost)."""
    long = str(_long_mission(tmp_path / "long.mission", 50_000))  # ~40 s, ~440 MB to check here
    d = start_daemon(tmp_path, daemon_cfg="load_timeout_s = 2.0")
    try:
        for _ in range(2):  # the second is not refused as "being loaded": the first was cleared
            r = d.ctl("load", long, timeout_s=120)
            why = "not compiled and verified within 2 s (daemon.load_timeout_s)"
            assert r.returncode == 1 and why in r.stderr, (r.returncode, r.stderr)
    finally:
        d.stop()
    d = start_daemon(tmp_path, daemon_cfg="load_memory_mb = 256")
    try:
        r = d.ctl("load", long, timeout_s=120)
        why = "needed more than 256 MB (daemon.load_memory_mb)"
        assert r.returncode == 1 and why in r.stderr, (r.returncode, r.stderr)
        assert d.call("load", path=DEMO)["mission"]["name"] == "PickDemo"  # type: ignore[index]
    finally:
        d.stop()


def test_a_load_under_way_when_the_daemon_stops_ends_with_it(tmp_path: Path) -> None:
    """The compiler runs in a session of its own: the daemon stopping kills it (before: a 50,000-
    motion compile went on for minutes after its daemon had gone)."""
    long = str(_long_mission(tmp_path / "long.mission", 50_000))
    d = start_daemon(tmp_path)
    try:
        with Client(d.socket) as c:
            c.sock.sendall((json.dumps({"id": 1, "cmd": "load", "args": {"path": long}}) + "\n").encode())
            end = time.monotonic() + 30
            while not _compilers(long):
                assert time.monotonic() < end, "no compiler process"
                time.sleep(0.1)
    finally:
        d.stop()
    end = time.monotonic() + 10
    while _compilers(long):
        assert time.monotonic() < end, "the compiler outlived its daemon"
        time.sleep(0.1)


def _compilers(mission: str) -> list[int]:
    out = []
    for p in Path("/proc").iterdir():
        with contextlib.suppress(OSError):
            mine = p.name.isdigit() and mission.encode() in (p / "cmdline").read_bytes()
            if mine and (p / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                out.append(int(p.name))
    return out


def test_a_log_goes_only_into_the_daemons_log_directory(daemon: Daemon, tmp_path: Path) -> None:
    for name, why in [
        ("../escape.csv", "a file name, not a path"),
        ("/etc/passwd", "a file name, not a path"),
        (".hidden.csv", "a file name, not a path"),
        ("x" * 300 + ".csv", "a file name, not a path"),
        ("run.txt", "end in .csv"),
    ]:
        r = daemon.reply("log", action="start", name=name)
        assert not r["ok"] and why in r["error"], (name, r)
    logs = Path(daemon.socket).parent / "logs"
    logs.mkdir(mode=0o750, exist_ok=True)
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (logs / "planted.csv").symlink_to(victim)  # a link planted where a log would be created
    r = daemon.reply("log", action="start", name="planted.csv")
    assert not r["ok"] and "already exists" in r["error"], r
    assert victim.read_text() == "keep me"
    info = daemon.call("log", action="start", name="ok.csv")
    assert Path(info["file"]) == logs / "ok.csv"  # type: ignore[index]
    assert not daemon.reply("log", action="start", name="ok.csv")["ok"]  # one log at a time
    daemon.call("log", action="stop")
    r = daemon.reply("log", action="start", name="ok.csv")  # never overwritten
    assert not r["ok"] and "already exists" in r["error"], r


def test_an_idle_connection_is_closed_and_its_slot_freed(tmp_path: Path) -> None:
    d = start_daemon(tmp_path, daemon_cfg="idle_timeout_s = 1.0")
    try:
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.settimeout(10)
        s.connect(d.socket)
        reply = json.loads(s.makefile("rb").readline())  # nothing sent: the daemon speaks first
        assert not reply["ok"] and "idle_timeout_s" in reply["error"]
        assert s.recv(1) == b""  # closed
        s.close()
        assert d.status()["state"] == "idle"
    finally:
        d.stop()


def _as_nobody_many(sock: str, n: int, cmd: str = "status") -> list[dict[str, object]]:
    """`n` connections held open at once by a forked child running as user nobody (its peer
    credentials), one request `cmd` on each; their replies."""
    nobody = pwd.getpwnam("nobody")
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.setgroups([])
            os.setgid(nobody.pw_gid)
            os.setuid(nobody.pw_uid)
            conns = []
            for _ in range(n):
                c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                c.settimeout(10)
                c.connect(sock)
                conns.append(c)
                time.sleep(0.05)  # accepted in order
            out = []
            for c in conns:
                with contextlib.suppress(OSError):  # refused at once: the daemon wrote why and closed
                    c.sendall(json.dumps({"cmd": cmd}).encode() + b"\n")
                out.append(json.loads(c.makefile("rb").readline()))
            os.write(w, json.dumps(out).encode())
        except BaseException as e:
            os.write(w, json.dumps([{"child_error": repr(e)}]).encode())
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as fh:
        data = fh.read()
    os.waitpid(pid, 0)
    replies: list[dict[str, object]] = json.loads(data)
    return replies


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run a client as another user")
def test_read_only_clients_cannot_take_the_control_clients_places(tmp_path: Path) -> None:
    _reachable_by_nobody(tmp_path)
    cfg = 'socket_group = "nogroup"\nread_groups = ["nogroup"]\nread_clients = 2'
    d = start_daemon(tmp_path, daemon_cfg=cfg)
    try:
        replies = _as_nobody_many(d.socket, 4)
        assert "child_error" not in replies[0], replies
        assert [r["ok"] for r in replies] == [True, True, False, False], replies
        assert all("too many clients with the read role (max 2)" in str(r["error"]) for r in replies[2:])
        assert d.status()["state"] == "idle"  # control clients are served meanwhile
    finally:
        d.stop()


def test_abort_is_not_held_up_by_a_load_under_way(daemon: Daemon) -> None:
    """A load compiles for a while (a child process); an abort sent meanwhile is answered at once,
    not after the load (the link to the real-time process carries both at the same time)."""
    times: dict[str, float] = {}

    def load() -> None:
        times["load_sent"] = time.monotonic()
        daemon.call("load", path=DEMO)
        times["load_done"] = time.monotonic()

    t = threading.Thread(target=load)
    t.start()
    end = time.monotonic() + 10
    while not _compilers(str(DEMO)):  # the load is under way: its compiler runs
        assert time.monotonic() < end and t.is_alive(), "no compiler process seen"
        time.sleep(0.002)
    t0 = time.monotonic()
    assert daemon.call("abort") == {"aborted": True}
    abort_s = time.monotonic() - t0
    t.join(timeout=60)
    load_s = times["load_done"] - times["load_sent"]
    # ratios, not timings: held up behind the load, the abort would take most of its time
    assert abort_s < 0.5 * load_s, (abort_s, load_s)


def _sockets_of(pid: int) -> int:
    n = 0
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(FileNotFoundError):  # closed meanwhile
            n += "socket" in os.readlink(f"/proc/{pid}/fd/{fd}")
    return n


def test_a_client_that_stops_reading_is_cut_off_and_its_connection_freed(tmp_path: Path) -> None:
    d = start_daemon(tmp_path, daemon_cfg="stall_timeout_s = 1.0")
    try:
        cmdd = int(d.call("ping")["pid"])  # type: ignore[index]
        time.sleep(0.5)
        before = _sockets_of(cmdd)
        stalled = []
        for _ in range(4):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.connect(d.socket)
            s.sendall(
                b'{"id": 1, "cmd": "monitor", "args": {"rate_hz": 500, "signals": ["q", "dq", "tau"]}}\n'
            )
            stalled.append(s)  # never read: the daemon's buffer for it fills
        end = time.monotonic() + 10
        while _sockets_of(cmdd) < before + 4:  # each accepted
            assert time.monotonic() < end, _sockets_of(cmdd) - before
            time.sleep(0.02)
        end = time.monotonic() + 20
        while _sockets_of(cmdd) > before:
            assert time.monotonic() < end, f"{_sockets_of(cmdd) - before} stalled connections still held"
            time.sleep(0.2)
        for s in stalled:
            s.close()
        assert d.status()["state"] == "idle"
    finally:
        d.stop()


def test_streams_whose_clients_left_free_their_slots_and_a_counted_monitor_ends_at_once(
    daemon: Daemon,
) -> None:
    for req in (
        b'{"id": 1, "cmd": "monitor", "args": {"rate_hz": 0.01}}\n',
        b'{"id": 1, "cmd": "events", "args": {"follow": true}}\n',
    ):
        for _ in range(20):  # more than daemon.control_clients (16): each must have been freed
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
                s.settimeout(10)
                s.connect(daemon.socket)
                s.sendall(req)
                time.sleep(0.05)  # the stream has begun (events: nothing to say yet); the client leaves
        time.sleep(0.5)
        assert daemon.status()["state"] == "idle"  # a control client still gets a slot
    t0 = time.monotonic()
    with Client(daemon.socket) as c:
        items = list(c.stream("monitor", rate_hz=0.01, count=1))
    assert len(items) == 2  # the header, the one sample; then the final reply
    assert time.monotonic() - t0 < 10  # at once, not after the 100 s period

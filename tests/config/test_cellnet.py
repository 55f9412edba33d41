"""`[cell]`: a daemon as a peer of a cell of robot PCs. Every mistake names the file, the key,
the value and what is allowed; roles only with TLS; the shipped cell reads."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.cellnet.zconfig import access_control, console_access_control, zenoh_config
from orccadd.config.cellnet import load_cellnet
from orccadd.config.station import read_station_config
from orccadd.errors import ConfigError
from tests.conftest import ROOT


def tls(tmp: Path) -> dict[str, str]:
    for name in ("ca.pem", "me.pem", "me.key"):
        (tmp / name).write_text("-")
    return {"ca": "ca.pem", "certificate": "me.pem", "private_key": "me.key"}


@pytest.mark.parametrize(
    ("table", "key", "words"),
    [
        ({"name": "a/b"}, "cell.name", "letters, digits, _ or -"),
        ({"name": "c", "robot": "x*"}, "cell.robot", "(='x*')"),
        ({"name": "c", "listen": ["127.0.0.1:7447"]}, "cell.listen[0]", "PROTO/HOST:PORT"),
        ({"name": "c", "connect": ["tls/127.0.0.1:7447"]}, "cell.connect[0]", "needs the TLS files"),
        ({"name": "c", "control": ["console"]}, "cell.control", "the cell is read-only without"),
        ({"name": "c", "ca": "ca.pem"}, "cell.certificate", "TLS needs ca, certificate and private_key"),
        ({"name": "c", "joints_hz": 5000}, "cell.joints_hz", "must be in [0, 500]"),
        ({"name": "c", "colour": 1}, "cell.colour", "is not a known key"),
    ],
)
def test_a_wrong_cell_table_names_the_key_and_what_is_allowed(
    tmp_path: Path, table: dict[str, object], key: str, words: str
) -> None:
    with pytest.raises(ConfigError) as e:
        load_cellnet(table, str(tmp_path / "r.toml"), "robot")
    assert e.value.key == key and words in str(e.value), str(e.value)


def test_with_tls_every_endpoint_is_secured_and_the_files_exist(tmp_path: Path) -> None:
    files = tls(tmp_path)
    with pytest.raises(ConfigError, match=r"cell.listen\[0\] \(='tcp/127.0.0.1:1'\) is not secured"):
        load_cellnet({"name": "c", "listen": ["tcp/127.0.0.1:1"], **files}, str(tmp_path / "r.toml"), "r")
    with pytest.raises(ConfigError, match="cell.ca .*no such file"):
        load_cellnet({"name": "c", **files, "ca": "nope.pem"}, str(tmp_path / "r.toml"), "r")
    net = load_cellnet({"name": "c", **files, "control": ["console"]}, str(tmp_path / "r.toml"), "r")
    assert net.robot == "r" and net.secured and net.tls_files()[0] == tmp_path / "ca.pem"


def test_the_access_control_denies_by_default_and_grants_by_certificate_name(tmp_path: Path) -> None:
    files = tls(tmp_path)
    net = load_cellnet(
        {"name": "c", **files, "control": ["console", "arm-b"], "read": ["viewer"]},
        str(tmp_path / "r.toml"),
        "arm-a",
    )
    acl = access_control(net)
    assert acl["enabled"] and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    policies = {p["subjects"][0]: set(p["rules"]) for p in acl["policies"]}
    assert "control" in policies["peer:console"] and "control" not in policies["peer:viewer"]
    assert rules["control"]["key_exprs"] == ["orccadd/c/arm-a/control"]
    assert rules["own:viewer"]["key_exprs"] == ["orccadd/c/viewer/**"]  # under its own name only,
    assert rules["own:viewer"]["messages"] == ["liveliness_token"]  # and a read peer puts nothing
    assert "put" in rules["own:console"]["messages"]  # a control peer's signals
    conf = zenoh_config(net, daemon=True)
    assert conf["scouting"]["multicast"]["enabled"] is False
    assert conf["transport"]["link"]["tls"]["enable_mtls"] is True
    assert "access_control" not in zenoh_config(net, daemon=False)  # a peer that names no daemons


def test_a_console_takes_in_only_what_each_of_its_daemons_says_under_its_own_name(tmp_path: Path) -> None:
    net = load_cellnet(
        {"name": "c", **tls(tmp_path), "daemons": ["arm-a", "arm-b"]}, str(tmp_path / "k.toml"), "console"
    )
    acl = zenoh_config(net, daemon=False)["access_control"]
    assert acl == console_access_control(net) and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    subjects = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    assert subjects == {"daemon:arm-a": ["arm-a"], "daemon:arm-b": ["arm-b"]}
    said = rules["says:arm-b"]
    assert said["flows"] == ["ingress"] and said["key_exprs"] == ["orccadd/c/arm-b/**"]
    assert {"reply", "put", "liveliness_token", "declare_queryable"} <= set(said["messages"])
    trusted = {p["id"]: (set(p["rules"]), p["subjects"]) for p in acl["policies"]}
    assert trusted["trust:arm-a"] == ({"interest", "says:arm-a"}, ["daemon:arm-a"])  # not arm-b's keys
    assert all("reply" not in r["messages"] for r in acl["rules"] if r["flows"] == ["ingress"] and
               r["key_exprs"] == ["**"])  # fmt: skip


def test_a_console_with_tls_must_name_its_daemons(tmp_path: Path) -> None:
    from orccadd.cellnet.console import read_console_config

    files = tls(tmp_path)
    path = tmp_path / "console.toml"
    path.write_text("[cell]\nname = \"c\"\nrobot = \"console\"\n" + "".join(
        f'{k} = "{v}"\n' for k, v in files.items()))  # fmt: skip
    with pytest.raises(ConfigError) as e:
        read_console_config(str(path))
    assert e.value.key == "cell.daemons" and "takes answers only from the daemons it names" in str(e.value)


def test_the_shipped_cell_configs_read(tmp_path: Path) -> None:
    certs = ROOT / "configs/cell/certs"
    if not (certs / "ca.pem").is_file():
        pytest.skip("configs/cell/certs/ is made by `make setup`")
    for arm in ("arm-a", "arm-b"):
        cell = read_station_config(ROOT / f"configs/cell/{arm}.toml")
        assert cell.cell is not None and cell.cell.robot == arm and cell.cell.secured
        assert cell.names == ("arm",)


def test_a_resource_of_a_cell_file_cannot_carry_its_own_cell_table(tmp_path: Path) -> None:
    robot = (ROOT / "configs/robots/sim-ur5e.toml").read_text().replace('"../', f'"{ROOT}/configs/')
    (tmp_path / "arm.toml").write_text(robot + '\n[cell]\nname = "c"\n')
    (tmp_path / "cell.toml").write_text('name = "x"\n[[resources]]\nname = "arm"\nconfig = "arm.toml"\n')
    with pytest.raises(ConfigError, match=r"resources\[0\].config .*has a \[cell\] table"):
        read_station_config(tmp_path / "cell.toml")

"""`[cell]`: a daemon (or a console) as a peer of a cell of robot PCs over Zenoh.

    [cell]
    name = "demo"                        # the cell: every key is under orccadd/<name>/
    robot = "arm-a"                      # this peer's name in the cell (default: the config's
                                         # name); with TLS, its certificate's common name
    listen = ["tls/127.0.0.1:7447"]      # default: loopback, a port of the system's choosing
    connect = ["tls/127.0.0.1:7448"]     # the peers to reach (explicit: no multicast scouting)
    ca = "certs/ca.pem"                  # TLS with mutual authentication: all three or none
    certificate = "certs/arm-a.pem"
    private_key = "certs/arm-a.key"
    control = ["console", "arm-b"]       # certificate names with the control role here
    read = ["viewer"]                    # with the read role only (control ⊃ read)
    daemons = ["arm-a", "arm-b"]         # a console's: the daemons it takes answers from
    signal_rate_hz = 200                 # a control peer's signals taken per second (1-1000)...
    signal_burst = 50                    # ... and at once (1-1000); beyond: dropped, counted, said
    read_requests_max = 16               # requests on `read` served at once (1-256; beyond: busy)
    control_requests_max = 16            # on `control` (1-256): a share a read flood cannot take

A peer's role here comes from its certificate (Zenoh's access control matches its common
name), never from what it says. A console runs its own side of that control: it takes
replies, samples and liveliness tokens under `orccadd/<cell>/<D>/` only from the certificate
named D, and only for the daemons in `daemons`; every other peer reaches nothing in it (a
certificate of the same authority cannot answer for a daemon, nor show a robot that is not
there). Without the TLS files the cell is read-only: nobody controls this
daemon from it, and no remote input enters its missions. Paths are relative to the config file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from orccadd.config.schema import field, load_dataclass
from orccadd.errors import ConfigError

NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_-]{0,62}$")  # one chunk of a key expression
ENDPOINT = re.compile(r"^(tcp|tls|quic|udp)/[^/\s]+:\d{1,5}$")
SECURED = ("tls", "quic")


@dataclass(frozen=True)
class CellNetConfig:
    name: str = field(doc="the cell's name")
    robot: str = field(default="", doc="this peer's name in the cell (default: the config's name)")
    listen: tuple[str, ...] = field(default=(), doc="Zenoh endpoints to listen on")
    connect: tuple[str, ...] = field(default=(), doc="Zenoh endpoints of peers to reach")
    scouting: bool = field(default=False, doc="multicast scouting (off: explicit endpoints)")
    ca: str = field(default="", doc="TLS: the certificate authority's PEM file")
    certificate: str = field(default="", doc="TLS: this peer's certificate (PEM)")
    private_key: str = field(default="", doc="TLS: this peer's private key (PEM)")
    control: tuple[str, ...] = field(default=(), doc="certificate names with the control role")
    read: tuple[str, ...] = field(default=(), doc="certificate names with the read role")
    daemons: tuple[str, ...] = field(
        default=(), doc="a console's: the daemons (certificate names) it takes answers from"
    )
    joints_hz: float = field(default=50.0, bounds=(0.0, 500.0), doc="joint states published (0: none)")
    status_hz: float = field(default=2.0, bounds=(0.1, 50.0), doc="status published")
    signal_rate_hz: float = field(
        default=200.0,
        bounds=(1.0, 1000.0),
        doc="a control peer's signals taken per second, on average (beyond: dropped and counted)",
    )
    signal_burst: int = field(default=50, bounds=(1, 1000), doc="... and at once, above that rate")
    read_requests_max: int = field(
        default=16, bounds=(1, 256), doc="requests on the read key served at once (beyond: `busy` at once)"
    )
    control_requests_max: int = field(
        default=16, bounds=(1, 256), doc="requests on the control key served at once (its own share)"
    )
    ros2: bool = field(default=False, doc="also publish for ROS 2 (rmw_zenoh)")
    ros2_domain_id: int = field(default=0, bounds=(0, 232))
    source: str = ""  # the file it was read from (set by the loader)

    @property
    def secured(self) -> bool:
        return bool(self.ca)

    def resolve(self, path: str) -> Path:
        return (Path(self.source).parent / path).resolve()

    def tls_files(self) -> tuple[Path, Path, Path]:
        """(ca, certificate, private key), absolute."""
        return self.resolve(self.ca), self.resolve(self.certificate), self.resolve(self.private_key)


def load_cellnet(raw: Any, file: str, default_robot: str, key: str = "cell") -> CellNetConfig:
    """The `[cell]` table of `file`, checked: names, endpoints, TLS files all or none and present,
    roles only with TLS. `ConfigError` naming `key.FIELD`, the value and what is allowed."""
    if not isinstance(raw, dict):
        raise ConfigError(file, key, f"(={raw!r}) must be a table")
    net = replace(load_dataclass(CellNetConfig, raw, file, key), source=file)
    net = replace(net, robot=net.robot or default_robot)
    for name, value in (("name", net.name), ("robot", net.robot)):
        if not NAME.match(value):
            raise ConfigError(
                file, f"{key}.{name}", f"(={value!r}) must be 1-63 letters, digits, _ or - (a key chunk)"
            )
    for name in ("listen", "connect"):
        for i, ep in enumerate(getattr(net, name)):
            if not ENDPOINT.match(ep):
                raise ConfigError(
                    file,
                    f"{key}.{name}[{i}]",
                    f"(={ep!r}) must be PROTO/HOST:PORT with PROTO tcp, tls, quic or udp",
                )
            if net.secured and ep.split("/", 1)[0] not in SECURED:
                raise ConfigError(
                    file,
                    f"{key}.{name}[{i}]",
                    f"(={ep!r}) is not secured: with TLS files every endpoint is tls/ or quic/",
                )
            if not net.secured and ep.split("/", 1)[0] in SECURED:
                raise ConfigError(
                    file,
                    f"{key}.{name}[{i}]",
                    f"(={ep!r}) needs the TLS files (ca, certificate, private_key)",
                )
    tls = {"ca": net.ca, "certificate": net.certificate, "private_key": net.private_key}
    if any(tls.values()) and not all(tls.values()):
        missing = [k for k, v in tls.items() if not v]
        raise ConfigError(
            file, f"{key}.{missing[0]}", "is missing: TLS needs ca, certificate and private_key"
        )
    for k, v in tls.items():
        if v and not net.resolve(v).is_file():
            raise ConfigError(
                file,
                f"{key}.{k}",
                f"(={v!r}): no such file (relative to {Path(file).parent}); in a checkout, `make setup` "
                "makes the shipped cell's test certificates",
            )
    for name in ("control", "read", "daemons"):
        names = getattr(net, name)
        if names and not net.secured:
            raise ConfigError(
                file,
                f"{key}.{name}",
                f"(={list(names)!r}) needs TLS (ca, certificate, private_key): the cell is read-only without",
            )
        for i, n in enumerate(names):
            if not NAME.match(n):
                raise ConfigError(
                    file,
                    f"{key}.{name}[{i}]",
                    f"(={n!r}) must be a certificate's common name (letters, digits, _ or -)",
                )
    return net

"""Test certificates for a cell: a certificate authority of its own and one certificate per peer
(its common name the peer's name in the cell), made with `openssl` (ECDSA P-256, X.509 v3).

For a cell on one machine and for tests, never for production: a real cell's authority is the
plant's, its keys kept off the robot PCs but each one's own. Keys are written 0600 and never
committed (`configs/cell/certs/` is made at setup and ignored by git).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

CA = "ca"
DAYS = 365
PEER_EXTENSIONS = (
    "basicConstraints=critical,CA:FALSE\n"
    "keyUsage=critical,digitalSignature\n"
    "extendedKeyUsage=serverAuth,clientAuth\n"
    "subjectAltName=DNS:localhost,IP:127.0.0.1\n"
)


class CertError(Exception):
    pass


def _openssl(*args: str) -> None:
    exe = shutil.which("openssl")
    if exe is None:
        raise CertError("making test certificates needs openssl (apt-get install openssl)")
    r = subprocess.run([exe, *args], capture_output=True, text=True, timeout=60, check=False)
    if r.returncode != 0:
        raise CertError(f"openssl {args[0]}: {r.stderr.strip()[-400:]}")


def make_ca(out: Path, name: str = "orccadd test cell CA") -> None:
    """`out/ca.pem` and `out/ca.key`, if not there yet."""
    if (out / f"{CA}.pem").is_file() and (out / f"{CA}.key").is_file():
        return
    _openssl(
        "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
        "-keyout", str(out / f"{CA}.key"), "-out", str(out / f"{CA}.pem"), "-days", str(DAYS),
        "-subj", f"/CN={name}",
        "-addext", "basicConstraints=critical,CA:TRUE",
        "-addext", "keyUsage=critical,keyCertSign,cRLSign",
    )  # fmt: skip
    os.chmod(out / f"{CA}.key", 0o600)


def make_peer(out: Path, name: str, ca_dir: Path | None = None) -> None:
    """`out/NAME.pem` and `out/NAME.key`, signed by the authority in `ca_dir` (default `out`)."""
    ca = ca_dir or out
    with tempfile.TemporaryDirectory() as tmp:
        csr, ext = Path(tmp) / "peer.csr", Path(tmp) / "peer.ext"
        ext.write_text(PEER_EXTENSIONS)
        _openssl(
            "req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
            "-keyout", str(out / f"{name}.key"), "-out", str(csr), "-subj", f"/CN={name}",
        )  # fmt: skip
        os.chmod(out / f"{name}.key", 0o600)
        _openssl(
            "x509", "-req", "-in", str(csr), "-CA", str(ca / f"{CA}.pem"), "-CAkey", str(ca / f"{CA}.key"),
            "-CAcreateserial", "-CAserial", str(Path(tmp) / "ca.srl"),
            "-out", str(out / f"{name}.pem"), "-days", str(DAYS), "-extfile", str(ext),
        )  # fmt: skip


def make_cell_certs(out: Path, names: Sequence[str]) -> Path:
    """An authority in `out` (kept if there) and a certificate for each name not there yet."""
    out.mkdir(parents=True, exist_ok=True)
    make_ca(out)
    for n in names:
        if not ((out / f"{n}.pem").is_file() and (out / f"{n}.key").is_file()):
            make_peer(out, n)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m orccadd.cellnet.certs DIR NAME…`: a test authority in DIR and a certificate for
    each NAME (kept if there)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m orccadd.cellnet.certs", description=main.__doc__)
    ap.add_argument("dir", type=Path)
    ap.add_argument("names", nargs="+")
    a = ap.parse_args(argv)
    try:
        make_cell_certs(a.dir, a.names)
    except (CertError, OSError) as e:
        ap.exit(1, f"{ap.prog}: error: {e}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

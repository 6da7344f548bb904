"""Real crossroads servers for the service tests: a throwaway PKI, the
replay server and the learner started from the binary that CROSSROADS_BIN
names, on loopback ports, and a TCP relay that can cut its connections."""

from __future__ import annotations

import datetime
import ipaddress
import os
import queue
import re
import select
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path
from typing import List, Optional

import pytest

TOKEN = "c0rrect-h0rse-battery-staple"


def required() -> bool:
    """Whether a missing tool fails the tests (CROSSROADS_REQUIRE_PYTHON=1,
    as ``make test`` sets) instead of skipping them."""
    return os.environ.get("CROSSROADS_REQUIRE_PYTHON") == "1"


def skip_or_fail(reason: str) -> None:
    if required():
        pytest.fail(f"{reason} (CROSSROADS_REQUIRE_PYTHON=1)")
    pytest.skip(reason)


ROOT = Path(__file__).resolve().parents[2]


def binary() -> str:
    """The crossroads binary: CROSSROADS_BIN, else the workspace's release
    or debug build; the test skips without one."""
    path = os.environ.get("CROSSROADS_BIN")
    for profile in ("release", "debug"):
        candidate = ROOT / "target" / profile / "crossroads"
        if not path and candidate.exists():
            path = str(candidate)
    if not path:
        skip_or_fail(
            "no crossroads binary: set CROSSROADS_BIN (or cargo build --release, "
            "target/release/crossroads) to start real servers"
        )
    if not os.access(path, os.X_OK):
        skip_or_fail(f"CROSSROADS_BIN={path} is not an executable file")
    return path


class Pki:
    """PEM files in ``dir``: a CA, a server certificate for localhost and
    127.0.0.1 signed by it, another CA that signed nothing here, and the
    token."""

    def __init__(self, dir: Path) -> None:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

        self.dir = dir
        now = datetime.datetime.now(datetime.timezone.utc)

        def name(cn: str) -> x509.Name:
            return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])

        def ca(cn: str):
            key = ec.generate_private_key(ec.SECP256R1())
            cert = (
                x509.CertificateBuilder()
                .subject_name(name(cn))
                .issuer_name(name(cn))
                .public_key(key.public_key())
                .serial_number(x509.random_serial_number())
                .not_valid_before(now - datetime.timedelta(hours=1))
                .not_valid_after(now + datetime.timedelta(days=1))
                .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
                .add_extension(
                    x509.KeyUsage(
                        digital_signature=False,
                        content_commitment=False,
                        key_encipherment=False,
                        data_encipherment=False,
                        key_agreement=False,
                        key_cert_sign=True,
                        crl_sign=True,
                        encipher_only=False,
                        decipher_only=False,
                    ),
                    critical=True,
                )
                .sign(key, hashes.SHA256())
            )
            return key, cert

        ca_key, ca_cert = ca("crossroads test CA")
        _, stranger = ca("someone else's CA")
        key = ec.generate_private_key(ec.SECP256R1())
        server = (
            x509.CertificateBuilder()
            .subject_name(name("server"))
            .issuer_name(ca_cert.subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(hours=1))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(
                x509.SubjectAlternativeName(
                    [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
                ),
                critical=False,
            )
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
            .sign(ca_key, hashes.SHA256())
        )
        pem = serialization.Encoding.PEM
        self.ca = dir / "ca.pem"
        self.ca.write_bytes(ca_cert.public_bytes(pem))
        self.stranger_ca = dir / "stranger-ca.pem"
        self.stranger_ca.write_bytes(stranger.public_bytes(pem))
        self.cert = dir / "server.pem"
        self.cert.write_bytes(server.public_bytes(pem))
        self.key = dir / "server.key"
        self.key.write_bytes(
            key.private_bytes(pem, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
        )
        self.token = dir / "token"
        self.token.write_text(TOKEN + "\n")

    def server_args(self) -> List[str]:
        """``--set`` flags for a role: TLS and the token on its server, and
        on its clients (the learner's replay client)."""
        sets = {
            "transport.tls.cert_file": self.cert,
            "transport.tls.key_file": self.key,
            "transport.tls.ca_file": self.ca,
            "transport.auth.token_file": self.token,
        }
        args = [
            # With TLS on, the config insists on https:// endpoints.
            "--set",
            "transport.replay_endpoint=https://127.0.0.1:50051",
            "--set",
            "transport.learner_endpoint=https://127.0.0.1:50052",
        ]
        for k, v in sets.items():
            args += ["--set", f"{k}={v}"]
        # Only the file counts, not the test process's CROSSROADS_TOKEN.
        return args + ["--set", 'transport.auth.token_env=""']


class Role:
    """A running ``crossroads <role>`` process, its standard error read
    line by line; :meth:`stop` sends SIGTERM and waits."""

    def __init__(self, args: List[str], needle: str, log: Path, timeout: float = 120.0) -> None:
        env = dict(os.environ, RUST_LOG="info", NO_COLOR="1")
        self.log = log
        self._file = open(log, "ab")
        self.process = subprocess.Popen(
            [binary(), *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env
        )
        self._lines: "queue.Queue[Optional[str]]" = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        self.addr = self._wait_for(needle, timeout)

    def _read(self) -> None:
        assert self.process.stderr is not None
        with self._file:
            for raw in self.process.stderr:
                self._file.write(raw)
                self._file.flush()
                self._lines.put(raw.decode("utf-8", "replace"))
        self._lines.put(None)

    def _wait_for(self, needle: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            try:
                line = self._lines.get(timeout=max(left, 0.01))
            except queue.Empty:
                line = ""
            if line is None or left <= 0:
                self.kill()
                raise AssertionError(f"never logged {needle!r}; see {self.log}:\n{self.tail()}")
            if needle in line:
                m = re.search(r"addr=(\S+)", line)
                assert m, f"no addr= in {line!r}"
                return m.group(1)

    def tail(self, n: int = 30) -> str:
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return ""

    def stop(self, timeout: float = 60.0) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill()
                raise AssertionError(f"no exit {timeout}s after SIGTERM:\n{self.tail()}") from None

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Relay:
    """A TCP relay on a loopback port to ``target`` (``host:port``);
    :meth:`cut` closes every connection it carries, as a network would."""

    def __init__(self, target: str) -> None:
        host, port = target.rsplit(":", 1)
        self.target = (host, int(port))
        self.listener = socket.socket()
        self.listener.bind(("127.0.0.1", 0))
        self.listener.listen()
        self.addr = "127.0.0.1:%d" % self.listener.getsockname()[1]
        self._pairs: List[tuple] = []
        #: Connections accepted so far.
        self.accepted = 0
        self._lock = threading.Lock()
        self._closed = False
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self._closed:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            try:
                upstream = socket.create_connection(self.target)
            except OSError:
                client.close()
                continue
            with self._lock:
                self._pairs.append((client, upstream))
                self.accepted += 1
            threading.Thread(target=self._pump, args=(client, upstream), daemon=True).start()

    def _pump(self, a: socket.socket, b: socket.socket) -> None:
        try:
            while True:
                ready, _, _ = select.select([a, b], [], [], 1.0)
                for s in ready:
                    data = s.recv(1 << 16)
                    if not data:
                        return
                    (b if s is a else a).sendall(data)
        except (OSError, ValueError):
            return
        finally:
            for s in (a, b):
                try:
                    s.close()
                except OSError:
                    pass

    def connections(self) -> int:
        with self._lock:
            return len(self._pairs)

    def cut(self) -> None:
        """Resets every connection now (new ones are still relayed)."""
        with self._lock:
            pairs, self._pairs = self._pairs, []
        for pair in pairs:
            for s in pair:
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def close(self) -> None:
        self._closed = True
        self.listener.close()
        self.cut()

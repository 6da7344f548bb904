"""The connection both clients share: endpoint, TLS, token, limits, and
the translation of gRPC errors into :mod:`crossroads.service.errors`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable, List, Optional, Tuple, TypeVar, Union

import grpc

from .errors import CrossroadsError, from_rpc_error

_C = TypeVar("_C", bound="Connection")

T = TypeVar("T")

#: The environment variable read for the token when none is given (the
#: roles' default, ``transport.auth.token_env``).
TOKEN_ENV = "CROSSROADS_TOKEN"

#: Largest message a client receives by default: a network's weights
#: travel in one message (the learner sends any size).
MAX_MESSAGE_BYTES = 1 << 30

PathLike = Union[str, "os.PathLike[str]"]


def _token(token: Optional[str], token_file: Optional[PathLike]) -> Optional[str]:
    """The token: ``token``, else ``token_file``'s contents, else
    ``$CROSSROADS_TOKEN`` when set and not empty, else none; checked as the
    servers check it (printable ASCII without spaces, surrounding
    whitespace dropped)."""
    if token is not None:
        text, origin = token, "the token"
    elif token_file is not None:
        try:
            text = Path(token_file).read_text()
        except OSError as e:
            raise ValueError(f"token_file {token_file}: cannot read it: {e}") from None
        origin = f"token_file {token_file}"
    else:
        text = os.environ.get(TOKEN_ENV, "")
        if not text.strip():
            return None
        origin = f"environment variable {TOKEN_ENV}"
    text = text.strip()
    if not text:
        raise ValueError(f"{origin} is empty")
    if not all(33 <= ord(c) <= 126 for c in text):
        raise ValueError(
            f"{origin} must be printable ASCII without spaces (it is sent in an HTTP header)"
        )
    return text


def _read(path: Optional[PathLike], what: str) -> Optional[bytes]:
    if path is None:
        return None
    try:
        return Path(path).read_bytes()
    except OSError as e:
        raise ValueError(f"{what} {path}: cannot read it: {e}") from None


class Connection:
    """A gRPC channel to one server with the caller's TLS and token.

    ``endpoint`` is ``https://host:port`` (TLS), ``http://host:port`` or
    ``host:port`` (plain TCP unless ``ca_file`` is given). ``ca_file``: the
    PEM CA certificates trusted for the server (without it, TLS uses the
    system's roots); ``server_name``: the name checked against the
    server's certificate instead of the endpoint's host;
    ``client_cert_file``/``client_key_file``: the client's certificate for
    servers that require one (mutual TLS). ``token`` (or ``token_file``,
    or ``$CROSSROADS_TOKEN``) is sent as ``authorization: Bearer <token>``
    on every call. ``timeout``: seconds a unary call may take.
    """

    def __init__(
        self,
        endpoint: str,
        *,
        ca_file: Optional[PathLike] = None,
        server_name: Optional[str] = None,
        client_cert_file: Optional[PathLike] = None,
        client_key_file: Optional[PathLike] = None,
        token: Optional[str] = None,
        token_file: Optional[PathLike] = None,
        timeout: float = 30.0,
        max_message_bytes: int = MAX_MESSAGE_BYTES,
    ) -> None:
        scheme, sep, target = endpoint.partition("://")
        if not sep:
            scheme, target = ("https" if ca_file is not None else "http"), endpoint
        if scheme not in ("http", "https"):
            raise ValueError(f"endpoint {endpoint!r}: the scheme must be http:// or https://")
        target = target.rstrip("/")
        if not target or "/" in target:
            raise ValueError(f"endpoint {endpoint!r}: expected [http[s]://]host:port")
        if scheme == "http" and (ca_file or server_name or client_cert_file):
            raise ValueError(f"endpoint {endpoint!r} is plain http://, but TLS settings were given")
        if (client_cert_file is None) != (client_key_file is None):
            raise ValueError("client_cert_file and client_key_file go together")
        self.endpoint = f"{scheme}://{target}"
        self.timeout = timeout
        token = _token(token, token_file)
        self._metadata: Tuple[Tuple[str, str], ...] = (
            (("authorization", f"Bearer {token}"),) if token else ()
        )
        options: List[Tuple[str, Union[int, str]]] = [
            ("grpc.max_receive_message_length", max_message_bytes),
            ("grpc.max_send_message_length", max_message_bytes),
            # gRPC waits up to 2 minutes between reconnections by default;
            # a restarted server should be found within seconds.
            ("grpc.initial_reconnect_backoff_ms", 100),
            ("grpc.max_reconnect_backoff_ms", 5_000),
        ]
        if scheme == "https":
            credentials = grpc.ssl_channel_credentials(
                root_certificates=_read(ca_file, "ca_file"),
                private_key=_read(client_key_file, "client_key_file"),
                certificate_chain=_read(client_cert_file, "client_cert_file"),
            )
            if server_name:
                options.append(("grpc.ssl_target_name_override", server_name))
            self.channel = grpc.secure_channel(target, credentials, options=options)
        else:
            self.channel = grpc.insecure_channel(target, options=options)

    @property
    def has_token(self) -> bool:
        return bool(self._metadata)

    def call(
        self, method: str, rpc: Callable[..., T], request, timeout: Optional[float] = None
    ) -> T:
        """A unary call, its failure as a typed error."""
        try:
            return rpc(
                request,
                timeout=self.timeout if timeout is None else timeout,
                metadata=self._metadata,
            )
        except grpc.RpcError as e:
            raise from_rpc_error(e, method) from None

    def stream(self, rpc: Callable[..., T], request, timeout: Optional[float] = None) -> T:
        """A server-streaming (or bidirectional) call, not yet started;
        iterate it under :func:`translate`."""
        return rpc(request, timeout=timeout, metadata=self._metadata)

    def close(self) -> None:
        self.channel.close()

    def __enter__(self: _C) -> _C:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class translate:
    """``with translate(method):`` turns a gRPC error raised inside into
    its typed :class:`CrossroadsError`."""

    def __init__(self, method: str) -> None:
        self.method = method

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, error, tb) -> bool:
        if isinstance(error, grpc.RpcError) and not isinstance(error, CrossroadsError):
            raise from_rpc_error(error, self.method) from None
        return False

"""The Foxglove bridge's front door: a WebSocket server (``websockets``) that checks each client's
Origin, speaks both names of the Foxglove WebSocket protocol v1, and relays frames to the
foxglove-sdk server listening on loopback.

Why a front door: foxglove-sdk 0.30.3's server (a) accepts only the subprotocol
``foxglove.sdk.v1`` and refuses clients that offer only the classic ``foxglove.websocket.v1``
(HTTP 400: the stock @foxglove/ws-protocol client, Lichtblick, older Foxglove), though both name the
same frames (serverInfo, advertise, subscribe, binary message data); and (b) has no hook to look at
a client's HTTP handshake, so it cannot refuse a web page on another site (Origin). The SDK keeps
doing the protocol (channels, subscriptions, client publishing); this module only decides who may
connect and copies frames both ways, one upstream connection per client.

The backend (issue 34, security): the SDK server has to listen on a TCP port (127.0.0.1) and offers
no hook for the handshake, so on its own any page in a browser on the robot could connect to it
directly and skip the Origin check. It therefore speaks only TLS (``wss://``), with a certificate
made for this run (:func:`backend_certificate`: a P-256 key made by ``openssl`` in a private
temporary directory, read into memory, the files deleted at once). The front door trusts exactly
that certificate (pinned). A browser refuses a ``wss://`` connection whose certificate no
authority signed, and never asks the user about a WebSocket, so a page cannot reach the backend
(a plain ``ws://`` handshake fails: the backend wants TLS). A local program that turns certificate
checks off can still connect, as it can to the front door itself (no Origin = a tool); what the
check is about is web pages. Without ``openssl`` the bridge does not start (fails closed).

Origin policy: a client without an Origin header (native apps, the npm client, tools) is accepted;
so are pages served from this machine (``localhost``, ``127.0.0.1``, ``[::1]``, any port) and the
origins named in ``allowed_origins`` (exact ``scheme://host[:port]``, e.g.
``https://app.foxglove.dev``). Any other Origin gets HTTP 403: a web page the operator happens to
open elsewhere cannot read the robot's topics through the operator's browser.
"""

from __future__ import annotations

import asyncio
import logging
import shutil
import ssl
import subprocess
import tempfile
import threading
from collections.abc import Sequence
from http import HTTPStatus
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from websockets.asyncio.client import ClientConnection
    from websockets.asyncio.server import Server, ServerConnection
    from websockets.http11 import Request, Response

LOG = logging.getLogger(__name__)

SUBPROTOCOLS = ('foxglove.sdk.v1', 'foxglove.websocket.v1')
"""Accepted names of protocol v1: the SDK's first (preferred when a client offers both)."""
UPSTREAM_SUBPROTOCOL = 'foxglove.sdk.v1'
LOCAL_HOSTS = frozenset({'localhost', '127.0.0.1', '::1'})
MAX_CLIENT_FRAME_BYTES = 1 << 20  # a client sends subscriptions and small messages (cmd_vel)


CERTIFICATE_DAYS = 3650
"""Validity of the backend's per-run certificate [days] (only the front door, in this process, trusts it)."""


def backend_certificate() -> tuple[bytes, bytes]:
    """(certificate, PKCS#8 private key), PEM, for ``127.0.0.1``, made fresh by ``openssl`` (about
    45 ms on this machine); InputError when openssl is missing or fails (the bridge fails closed)."""
    openssl = shutil.which('openssl')
    if openssl is None:
        raise InputError('cannot secure the Foxglove backend: the openssl program is not installed')
    with tempfile.TemporaryDirectory(prefix='skidsteer_foxglove_') as folder:  # mode 0700
        key, cert = Path(folder) / 'key.pem', Path(folder) / 'cert.pem'
        command = [
            openssl, 'req', '-x509', '-newkey', 'ec', '-pkeyopt', 'ec_paramgen_curve:P-256', '-nodes',
            '-keyout', str(key), '-out', str(cert), '-days', str(CERTIFICATE_DAYS),
            '-subj', '/CN=127.0.0.1', '-addext', 'subjectAltName=IP:127.0.0.1',
        ]  # fmt: skip
        try:
            subprocess.run(command, check=True, capture_output=True, timeout=30)
        except (OSError, subprocess.SubprocessError) as err:
            raise InputError(f'cannot secure the Foxglove backend: openssl failed ({err})') from err
        return cert.read_bytes(), key.read_bytes()


def pinned_context(certificate: bytes) -> ssl.SSLContext:
    """A TLS client context that trusts ``certificate`` (PEM) and nothing else (given ``cadata``,
    :func:`ssl.create_default_context` loads no system authorities), host name checked."""
    return ssl.create_default_context(cadata=certificate.decode('ascii'))


def origin_allowed(origin: str | None, allowed: Sequence[str]) -> bool:
    """True if a client with this Origin header may connect (module docstring)."""
    if origin is None:
        return True
    if origin.rstrip('/') in {a.rstrip('/') for a in allowed}:
        return True
    try:
        host = urlsplit(origin).hostname
    except ValueError:
        return False
    return host in LOCAL_HOSTS


class FrontDoor:
    """A WebSocket server at ``host``:``port`` (0: any free port) relaying to ``upstream_url``."""

    def __init__(
        self,
        host: str,
        port: int,
        upstream_url: str,
        allowed_origins: Sequence[str] = (),
        upstream_certificate: bytes | None = None,
    ) -> None:
        """``upstream_certificate``: the backend's certificate (PEM), pinned for a ``wss://``
        ``upstream_url`` (module docstring)."""
        self.upstream_url = upstream_url
        self._upstream_ssl = None if upstream_certificate is None else pinned_context(upstream_certificate)
        self.allowed_origins = tuple(allowed_origins)
        self.refused = 0
        self.connections = 0
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name='foxglove-front', daemon=True)
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(self._start(host, port), self._loop)
        try:
            self._server = future.result(timeout=10)
        except BaseException:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(5)
            raise
        self.port = int(self._server.sockets[0].getsockname()[1])

    async def _start(self, host: str, port: int) -> Server:
        from websockets.asyncio.server import serve
        from websockets.typing import Subprotocol

        return await serve(
            self._relay,
            host,
            port,
            subprotocols=[Subprotocol(name) for name in SUBPROTOCOLS],
            process_request=self._check_origin,
            compression=None,
            max_size=MAX_CLIENT_FRAME_BYTES,
        )

    def _check_origin(self, connection: ServerConnection, request: Request) -> Response | None:
        origin = request.headers.get('Origin')
        if origin_allowed(origin, self.allowed_origins):
            return None
        self.refused += 1
        LOG.warning('refused a Foxglove client from Origin %s (allow it with --allow-origin)', origin)
        return connection.respond(HTTPStatus.FORBIDDEN, f'Origin {origin} is not allowed\n')

    async def _relay(self, client: ServerConnection) -> None:
        from websockets.asyncio.client import connect
        from websockets.exceptions import ConnectionClosed
        from websockets.typing import Subprotocol

        self.connections += 1
        try:
            async with connect(
                self.upstream_url,
                subprotocols=[Subprotocol(UPSTREAM_SUBPROTOCOL)],
                compression=None,
                max_size=None,
                ssl=self._upstream_ssl,
            ) as upstream:

                async def pump(
                    source: ServerConnection | ClientConnection, sink: ServerConnection | ClientConnection
                ) -> None:
                    try:
                        async for frame in source:
                            await sink.send(frame)
                    except ConnectionClosed:
                        pass

                tasks = [
                    asyncio.create_task(pump(client, upstream)),
                    asyncio.create_task(pump(upstream, client)),
                ]
                _, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
                for task in pending:
                    task.cancel()
        except (OSError, ConnectionClosed) as err:
            LOG.warning('Foxglove relay ended: %s', err)

    def close(self) -> None:
        """Stop accepting, close every connection, stop the thread."""

        async def stop() -> None:
            self._server.close()
            await self._server.wait_closed()

        try:
            asyncio.run_coroutine_threadsafe(stop(), self._loop).result(timeout=10)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(10)

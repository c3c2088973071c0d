"""The ``arroch tablet`` process: configure, serve until SIGINT/SIGTERM, stop cleanly.

Order matters for clean failure and clean exit:

1. everything that can be wrong in the configuration (site, intrinsics file, certificate) fails
   first, with exit code 2 and one line, before any Zenoh session or socket exists;
2. the Zenoh bridge opens (exit 1 if it cannot), its worker runs on a thread;
3. the HTTPS server listens (exit 1 if the port is taken), the URLs and QR code are printed;
4. on SIGINT/SIGTERM: pages are told the server is going away (close 1001), the server stops,
   frame threads finish, the bridge's worker stops and closes the Zenoh session (bounded).
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

from aiohttp import web

from .announce import announce, certificate_names, hosts_to_announce, page_url
from .bridge import TabletBridge
from .intrinsics import CameraModel
from .security import ensure_certificate, new_token, server_ssl_context
from .server import ServerOptions, TabletServer

log = logging.getLogger("arroch.tablet")

EXIT_START = 1
EXIT_CONFIG = 2


@dataclass
class ListenOptions:
    host: str = "0.0.0.0"
    port: int = 8443
    public_host: str | None = None
    state_dir: Path | None = None
    qr: bool = True


async def _serve(server: TabletServer, ssl_context, listen: ListenOptions, token: str, mode_in_url: str | None) -> int:  # noqa: ANN001
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    runner = web.AppRunner(server.app, access_log=None, handle_signals=False, shutdown_timeout=2.0)
    await runner.setup()
    site = web.TCPSite(runner, listen.host or None, listen.port, ssl_context=ssl_context)
    try:
        await site.start()
    except OSError as exc:
        log.error("cannot listen on %s:%d: %s", listen.host, listen.port, exc)
        await runner.cleanup()
        return EXIT_START
    port = listen.port
    server_obj = getattr(site, "_server", None)
    if server_obj is not None and server_obj.sockets:
        port = server_obj.sockets[0].getsockname()[1]  # the real port when --port 0 asked for any
    hosts = hosts_to_announce(listen.host, listen.public_host)
    log.info("tablet server listening on https://%s:%d", listen.host or "*", port)
    announce([page_url(h, port, token, mode_in_url) for h in hosts], qr=listen.qr)
    await stop.wait()
    log.info("stopping")
    await runner.cleanup()
    return 0


def run_tablet(
    *, site, bridge: TabletBridge, camera_model: CameraModel, options: ServerOptions, listen: ListenOptions
) -> int:  # noqa: ANN001
    """Serve until a signal; returns the exit code. ``bridge`` is built but not yet open."""
    from runtime.certs import CertError

    from .security import default_state_dir

    hosts = hosts_to_announce(listen.host, listen.public_host)
    dns, ips = certificate_names(hosts)
    state_dir = Path(listen.state_dir) if listen.state_dir else default_state_dir()
    try:
        certificate = ensure_certificate(state_dir, dns, ips)
        ssl_context = server_ssl_context(certificate)
    except (CertError, OSError, ValueError) as exc:
        log.error("certificate in %s: %s", state_dir, exc)
        return EXIT_CONFIG
    log.info(
        "certificate %s (authority %s: install it on a tablet to trust this server)",
        certificate.cert,
        certificate.authority,
    )
    token = new_token()
    server = TabletServer(
        site=site,
        bridge=bridge,
        camera_model=camera_model,
        token=token,
        authority=certificate.authority,
        options=options,
    )
    try:
        bridge.open()
    except Exception as exc:
        log.error("could not start: %s", exc)
        bridge.close()
        server.close_pools()
        return EXIT_START
    worker = threading.Thread(target=bridge.run, name="tablet-zenoh", daemon=True)
    worker.start()
    code = 0
    try:
        # A study page's mode is the trial's, not the URL's.
        mode_in_url = "viewer" if options.default_mode == "viewer" and options.study is None else None
        code = asyncio.run(_serve(server, ssl_context, listen, token, mode_in_url))
    finally:
        server.close_pools()
        bridge.stop()
        worker.join(5.0)
    if bridge.close_timed_out or worker.is_alive():
        # Zenoh's close overran its budget (zenoh-python issue 434): leave now, output flushed.
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code

"""The meshcat server of a live viewer, run as a script by :class:`gaussim.viewer.Viewer`.

Usage: ``python viewer_server.py PARENT_PID`` with the page's overlay (HTML) on standard input; the
page at /static/ is meshcat's with that overlay. Unlike ``python -m meshcat.servers.zmqserver``, whose web
server listens on every address (tornado's ``listen(port)``; only its ZMQ socket honours ``host``), both of
its sockets are bound to 127.0.0.1, and it exits when the process that started it is gone (killed by
SIGKILL included), so no server outlives its run. Run by path, not as a module: it needs meshcat only,
not gaussim's import.
"""

import functools
import os
import sys
from pathlib import Path

import tornado.web
import umsgpack
from meshcat.servers.tree import find_node, walk
from meshcat.servers.zmqserver import VIEWER_HTML, VIEWER_ROOT, ZMQWebSocketBridge
from tornado.ioloop import PeriodicCallback

HOST = "127.0.0.1"
# How often the server checks that its parent is alive [ms].
WATCH_MS = 250


# Where the overlay goes in meshcat's page.
MARKER = '<script id="embedded-json">'


class OverlaidPage(tornado.web.RequestHandler):
    """meshcat's page (index.html) with gaussim's overlay, not cached (as meshcat serves it)."""

    page = ""

    def get(self, _: str) -> None:
        self.set_header("Cache-Control", "no-store, no-cache, must-revalidate, max-age=0")
        self.finish(self.page)


class LocalBridge(ZMQWebSocketBridge):
    """meshcat's bridge with its web server bound to HOST, like its ZMQ socket, and its page overlaid."""

    def make_app(self):  # type: ignore[no-untyped-def]
        app = super().make_app()
        # matched before meshcat's own routes (its scripts and its websocket)
        app.wildcard_router.add_rules([(rf"/static/(|{VIEWER_HTML})", OverlaidPage)])
        app.wildcard_router.rules.insert(0, app.wildcard_router.rules.pop())
        app.listen = functools.partial(app.listen, address=HOST)
        return app

    def handle_zmq(self, frames):  # type: ignore[no-untyped-def]
        """meshcat's, but a property set again replaces the node's old value (meshcat keeps them all,
        and sends them all to each page: a live run's clock, every frame)."""
        if len(frames) == 3 and frames[0] == b"set_property":
            node = find_node(self.tree, [p for p in frames[1].decode().split("/") if p])
            name = umsgpack.unpackb(frames[2])["property"]
            node.properties[:] = [p for p in node.properties if umsgpack.unpackb(p)["property"] != name]
        super().handle_zmq(frames)

    def send_scene(self, websocket):  # type: ignore[no-untyped-def]
        """The scene to a page that connects: its objects, properties and transforms, then its
        animation (meshcat sends the animation, held by the root, first: a page given it before the
        objects it moves froze)."""
        nodes = list(walk(self.tree))
        for node in nodes:
            for command in (node.object, *node.properties, node.transform):
                if command is not None:
                    websocket.write_message(command, binary=True)
        for node in nodes:
            if node.animation is not None:
                websocket.write_message(node.animation, binary=True)


def main() -> None:
    parent = int(sys.argv[1])
    page = (Path(VIEWER_ROOT) / VIEWER_HTML).read_text()
    OverlaidPage.page = page.replace(MARKER, sys.stdin.read() + MARKER, 1)
    bridge = LocalBridge(host=HOST)

    def watch() -> None:
        if os.getppid() != parent:  # reparented: the parent died without stopping us
            bridge.ioloop.stop()

    if os.getppid() != parent:
        return
    PeriodicCallback(watch, WATCH_MS).start()
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()

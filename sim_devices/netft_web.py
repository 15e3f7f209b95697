"""The Net F/T box's web server, as the RDT emulator (:mod:`ftc_hw.sim_devices.netft_rdt`) runs it: which
page a URL is, and the HTTP server on port 80 of the box's address (a free port, said, where 80 cannot be
bound). The pages' bytes: :mod:`ftc_hw.codecs.netft_pages`; what each follows: ``sim_devices/SOURCES.md``."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, TypeVar
from urllib.parse import parse_qs, urlsplit

from ftc_hw.codecs.netft_pages import CALIBRATION_PAGE, CONFIG_PAGE, CONFIGS, BoxInfo, calibration_page, config_page
from ftc_hw.codecs.netft_rdt import Calibration

HTTP_PORT = 80  # where every client looks for the box's pages
S = TypeVar("S")


@dataclass(frozen=True)
class BoxPages:
    """What the box's pages are made of besides its state: its calibration and identity, the configuration
    page's elements replaced (``extra``) or the whole page (``fixed``, tests of bad pages), and its
    calibration page (None: none, 404)."""

    calibration: Calibration
    info: BoxInfo
    extra: dict[str, str] | None = None
    fixed: bytes | None = None
    calapi: bytes | None = None

    @classmethod
    def of(cls, calibration: Calibration, info: BoxInfo, options: dict[str, Any]) -> BoxPages:
        page = options.get("calibration_xml")
        calapi = None if options.get("calapi", True) is False else \
            calibration_page(calibration, info, options.get("calapi_fields"))
        return cls(calibration, info, options.get("calibration_fields"), None if page is None else str(page).encode(),
                   calapi)

    def page(self, url: str, reading: Sequence[int], bias: Sequence[int]) -> bytes | None:
        """The page at ``url`` (path and query) with the box's newest ``reading`` (biased) and its ``bias``,
        or None: not a page of the box (404), an index out of range or not a number too."""
        parts = urlsplit(url)
        index_text = parse_qs(parts.query).get("index", [None])[0]
        try:
            index = None if index_text is None else int(index_text)
        except ValueError:
            return None
        if parts.path == CONFIG_PAGE:
            if index is not None and not 0 <= index < CONFIGS:
                return None
            if self.fixed is not None:
                return self.fixed
            return config_page(self.calibration, self.info, index=0 if index is None else index, reading=reading,
                               bias=bias, extra=self.extra)
        if parts.path == CALIBRATION_PAGE and index in (None, 0):
            return self.calapi
        return None


def bind_web(host: str, port: int | None, serve: Callable[[str], bytes | None], counts: dict[str, int],
             fallback: bool = True) -> tuple[ThreadingHTTPServer, str]:
    """The box's web server on ``host``: ``port`` when given (bound or OSError), else 80, else (``fallback``)
    a free port, with the sentence that says so (empty when on 80 or as given). ``serve(url)`` gives a
    page or None (404); ``counts`` gets ``pages`` and ``page_errors``."""
    handler = _handler(serve, counts)
    return bind_server(lambda p: ThreadingHTTPServer((host, p), handler), port, HTTP_PORT, fallback,
                       f"the web server to {host}:{HTTP_PORT} ({{}}: port 80 needs root or CAP_NET_BIND_SERVICE, "
                       "and a free port); its pages are on port {} instead, where clients looking at port 80 do "
                       "not find them")


def bind_server(make: Callable[[int], S], port: int | None, default: int, fallback: bool,
                said: str) -> tuple[S, str]:
    """``make(port)`` when ``port`` is given (bound or OSError), else ``make(default)``, else (``fallback``)
    ``make(0)``, a free port, with the sentence that says so: "cannot bind " and ``said`` with the error and
    the free port in its two ``{}`` (empty where it should be)."""
    if port is not None:
        return make(port), ""
    try:
        return make(default), ""
    except OSError as exc:
        if not fallback:
            raise
        server = make(0)
        return server, "cannot bind " + said.format(exc.strerror or exc, server.server_address[1])  # type: ignore[attr-defined]


def _handler(serve: Callable[[str], bytes | None], counts: dict[str, int]) -> type[BaseHTTPRequestHandler]:
    class Page(BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            page = serve(self.path)
            if page is None:
                counts["page_errors"] += 1
                self.send_error(404)
                return
            counts["pages"] += 1
            self.send_response(200)
            self.send_header("Content-Type", "text/xml")
            self.send_header("Content-Length", str(len(page)))
            self.end_headers()
            self.wfile.write(page)

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - http.server's signature
            pass

    return Page

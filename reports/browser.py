"""Open a report in headless Chromium: screenshot, decoded images, console errors.

The page carries a small inline script (see ``templates/report.html``) that, on ``load``,
writes to ``<body>``: ``data-images-total``, ``data-images-ok`` (``complete`` and
``naturalWidth > 0``), ``data-images-bad`` and ``data-errors`` (uncaught errors, failed
resource loads and ``console.error`` calls). :func:`check_page` runs Chromium twice, once with
``--dump-dom`` (to read those attributes after the page's scripts ran) and once with
``--screenshot``, both with ``--enable-logging=stderr`` so that console messages Chromium
reports itself ("Uncaught ...", ``CONSOLE`` lines at error level) are caught as well.

Chromium is the Debian ``chromium`` package (``apt-get install chromium``); it runs with
``--headless --no-sandbox --disable-gpu`` and no network-facing features.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-default-apps", "--disable-extensions", "--hide-scrollbars", "--mute-audio",
         "--enable-logging=stderr", "--v=0")
CONSOLE_ERROR = re.compile(r"Uncaught|CONSOLE\(\d+\).*(?:error|Error)|:ERROR:CONSOLE|"
                           r"Failed to load resource", re.IGNORECASE)


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome executable, or None."""
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass
class PageCheck:
    """Outcome of :func:`check_page`."""

    images_total: int = 0
    images_ok: int = 0
    images_bad: str = ""
    page_errors: list = field(default_factory=list)
    console_errors: list = field(default_factory=list)
    screenshot: Path | None = None
    script_ran: bool = False
    attrs: dict = field(default_factory=dict)
    """Every ``data-*`` attribute of ``<body>`` after the page's scripts ran (a page may add its
    own, e.g. where an element ends on the first screen)."""

    @property
    def ok(self) -> bool:
        return (self.script_ran and self.images_total > 0 and self.images_ok == self.images_total
                and not self.page_errors and not self.console_errors and self.screenshot is not None
                and self.screenshot.exists())

    def text(self) -> str:
        return (f"browser check {'OK' if self.ok else 'FAILED'}: {self.images_ok}/{self.images_total} "
                f"images decoded, {len(self.page_errors)} page errors, {len(self.console_errors)} "
                f"console errors, script ran: {self.script_ran}, screenshot: {self.screenshot}"
                + (f"\n  bad images: {self.images_bad}" if self.images_bad else "")
                + "".join(f"\n  page error: {e}" for e in self.page_errors)
                + "".join(f"\n  console: {e}" for e in self.console_errors))


def _attr(dom: str, name: str) -> str | None:
    m = re.search(r"<body[^>]*\s" + re.escape(name) + r'="([^"]*)"', dom)
    return m.group(1) if m else None


def check_page(html: str | Path, screenshot: str | Path, *, chromium: str | None = None,
               width: int = 1280, height: int = 4000, timeout: float = 120.0) -> PageCheck:
    """Load ``html`` in headless Chromium, save a screenshot and report images and errors.

    Parameters
    ----------
    html : path
        The page (opened as a ``file://`` URL).
    screenshot : path
        PNG written by Chromium (``--window-size=width,height``).
    chromium : str, optional
        Executable (default: :func:`find_chromium`).

    Raises
    ------
    FileNotFoundError
        When no Chromium is installed.
    """
    exe = chromium or find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium executable found (apt-get install chromium)")
    url = Path(html).resolve().as_uri()
    screenshot = Path(screenshot).resolve()
    screenshot.parent.mkdir(parents=True, exist_ok=True)
    out = PageCheck()
    with tempfile.TemporaryDirectory(prefix="report-chromium-") as profile:
        base = [exe, *FLAGS, f"--user-data-dir={profile}", f"--window-size={width},{height}",
                "--virtual-time-budget=10000"]
        dom = subprocess.run([*base, "--dump-dom", url], capture_output=True, text=True,
                             timeout=timeout)
        shot = subprocess.run([*base, f"--screenshot={screenshot}", url], capture_output=True,
                              text=True, timeout=timeout)
    page = dom.stdout
    bodies = re.findall(r"<body[^>]*>", page)          # the last one is the element (not text)
    out.attrs = dict(re.findall(r'\s(data-[\w-]+)="([^"]*)"', bodies[-1])) if bodies else {}
    out.script_ran = _attr(page, "data-check") == "done"
    out.images_total = int(_attr(page, "data-images-total") or 0)
    out.images_ok = int(_attr(page, "data-images-ok") or 0)
    out.images_bad = _attr(page, "data-images-bad") or ""
    errs = _attr(page, "data-errors") or ""
    out.page_errors = [e for e in errs.split(" | ") if e]
    for stream in (dom.stderr, shot.stderr):
        for line in stream.splitlines():
            if CONSOLE_ERROR.search(line):
                out.console_errors.append(line.strip()[:300])
    if shot.returncode == 0 and screenshot.exists():
        out.screenshot = screenshot
    return out

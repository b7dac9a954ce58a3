"""A report page in a real browser: headless Chromium, driven over the DevTools protocol.

No Python package beyond the standard library: Chromium is started with
``--remote-debugging-pipe`` and spoken to in its own protocol (JSON messages
ended by a NUL byte, commands on its file descriptor 3, answers and events on
4). :func:`open_page` loads a page and returns every image's natural width and
every error the page logged: uncaught exceptions, ``console.error``, the
browser's own error log (a resource that failed to load lands there) and
failed requests.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import queue
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The names Chromium goes by (Debian's package installs ``chromium``).
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: How to install it (Debian; ``.ci/run`` does this where it is missing).
INSTALL_HINT = "apt-get update && apt-get install -y chromium chromium-driver"


def find_browser() -> str | None:
    """The path of a Chromium on PATH, or None."""
    return next((path for name in BROWSERS if (path := shutil.which(name))), None)


def require_browser() -> str:
    """Chromium's path; without one a skip that says why, or in CI (``CI=true``) a failure."""
    import pytest

    path = find_browser()
    if path is None:
        reason = f"no Chromium on PATH (install it: {INSTALL_HINT})"
        if os.environ.get("CI") == "true":
            pytest.fail(f"{reason}; CI=true: the report's browser check must run")
        pytest.skip(reason)
    return path


def assert_page_works(page: str | os.PathLike, browser: str) -> PageCheck:
    """Every image of ``page`` loads and the page logs no error, in a real browser."""
    check = open_page(page, browser)
    expected = Path(page).read_text(encoding="utf-8").count("<img ")
    assert len(check.images) == expected > 0, check.images
    assert check.broken_images == [], check.broken_images
    assert check.errors == (), "\n".join(check.errors)
    return check


@dataclass(frozen=True)
class Image:
    """One ``<img>`` of the page as the browser loaded it."""

    src: str
    natural_width: int


@dataclass(frozen=True)
class PageCheck:
    """What the page showed and logged: its images and its errors, in order."""

    title: str
    images: tuple[Image, ...]
    errors: tuple[str, ...]

    @property
    def broken_images(self) -> list[str]:
        return [image.src for image in self.images if image.natural_width <= 0]


class _Pipe:
    """Chromium's debugging pipe: numbered commands, their answers, and events."""

    def __init__(self, process: subprocess.Popen, commands: int, answers: int) -> None:
        self.process = process
        self.commands = os.fdopen(commands, "wb", buffering=0)
        self.inbox: queue.Queue[dict[str, Any]] = queue.Queue()
        self.events: list[dict[str, Any]] = []
        self._next_id = 0
        threading.Thread(target=self._read, args=(answers,), daemon=True).start()

    def _read(self, answers: int) -> None:
        buffer = b""
        with os.fdopen(answers, "rb", buffering=0) as stream:
            while chunk := stream.read(65536):
                buffer += chunk
                *messages, buffer = buffer.split(b"\0")
                for message in messages:
                    self.inbox.put(json.loads(message))

    def call(self, method: str, session: str | None = None, timeout: float = 60.0,
             **params: Any) -> dict[str, Any]:  # fmt: skip
        """Send one command and wait for its answer (events that come first are kept)."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        self.commands.write(json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            reply = self._get(deadline, method)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self.events.append(reply)

    def wait_for(self, method: str, timeout: float = 60.0) -> dict[str, Any]:
        """Wait for an event (one that came already counts)."""
        for event in self.events:
            if event.get("method") == method:
                return event
        deadline = time.monotonic() + timeout
        while True:
            event = self._get(deadline, method)
            self.events.append(event)
            if event.get("method") == method:
                return event

    def drain(self, seconds: float) -> None:
        """Keep the events that arrive within ``seconds``."""
        deadline = time.monotonic() + seconds
        with contextlib.suppress(queue.Empty):
            while (left := deadline - time.monotonic()) > 0:
                self.events.append(self.inbox.get(timeout=left))

    def _get(self, deadline: float, waiting_for: str) -> dict[str, Any]:
        try:
            return self.inbox.get(timeout=max(deadline - time.monotonic(), 0.01))
        except queue.Empty:
            raise TimeoutError(f"Chromium did not answer {waiting_for} in time") from None


def _high(fd: int) -> int:
    """A copy of ``fd`` above 2..4, so that placing the child's 3 and 4 clobbers nothing."""
    copy = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return copy


def _errors(events: list[dict[str, Any]]) -> list[str]:
    """The page's errors among the protocol's events, in words."""
    found = []
    for event in events:
        method, params = event.get("method"), event.get("params", {})
        if method == "Runtime.exceptionThrown":
            details = params["exceptionDetails"]
            text = details.get("exception", {}).get("description") or details.get("text")
            found.append(f"uncaught exception: {text}")
        elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
            words = " ".join(str(a.get("value", a.get("description", ""))) for a in params["args"])
            found.append(f"console.{params['type']}: {words}")
        elif method == "Log.entryAdded" and params["entry"]["level"] == "error":
            entry = params["entry"]
            found.append(f"log ({entry['source']}): {entry['text']} {entry.get('url', '')}".strip())
        elif method == "Network.loadingFailed" and not params.get("canceled"):
            found.append(f"request failed: {params.get('errorText')} ({params.get('type')})")
    return found


_IMAGES = (
    "JSON.stringify({title: document.title, images: Array.from(document.images, "
    "i => ({src: i.getAttribute('src'), width: i.complete ? i.naturalWidth : 0}))})"
)


def open_page(page: str | os.PathLike, browser: str, timeout: float = 120.0) -> PageCheck:
    """Load ``page`` (a file) in headless ``browser``; its images and the errors it logged."""
    url = Path(page).resolve().as_uri()
    command_read, command_write = (_high(fd) for fd in os.pipe())
    answer_read, answer_write = (_high(fd) for fd in os.pipe())

    def place_pipes() -> None:  # in the child, before exec
        os.dup2(command_read, 3)
        os.dup2(answer_write, 4)

    # Chromium's helper processes may still write to the profile while it is removed: a
    # leftover file there is no finding about the page.
    with tempfile.TemporaryDirectory(
        prefix="pm-joint-browser-", ignore_cleanup_errors=True
    ) as profile:
        process = subprocess.Popen(
            [browser, "--headless", "--remote-debugging-pipe", "--no-sandbox", "--disable-gpu",
             "--disable-dev-shm-usage", "--no-first-run", "--no-default-browser-check",
             "--disable-extensions", f"--user-data-dir={profile}", "about:blank"],
            pass_fds=(3, 4), preexec_fn=place_pipes, start_new_session=True,
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        os.close(command_read)
        os.close(answer_write)
        pipe = _Pipe(process, command_write, answer_read)
        try:
            target = pipe.call("Target.createTarget", url="about:blank", timeout=timeout)
            session = pipe.call("Target.attachToTarget", targetId=target["targetId"],
                                flatten=True)["sessionId"]  # fmt: skip
            for domain in ("Page", "Runtime", "Log", "Network"):
                pipe.call(f"{domain}.enable", session)
            pipe.call("Page.navigate", session, url=url)
            pipe.wait_for("Page.loadEventFired", timeout=timeout)
            pipe.drain(0.5)  # errors logged just after the load event
            found = pipe.call("Runtime.evaluate", session, expression=_IMAGES, returnByValue=True)
            pipe.drain(0.2)
            shown = json.loads(found["result"]["value"])
            with contextlib.suppress(Exception):
                pipe.call("Browser.close", timeout=10)
        finally:
            # The whole process group: the renderer and GPU helpers go with the browser.
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)
    return PageCheck(
        title=shown["title"],
        images=tuple(Image(i["src"], int(i["width"])) for i in shown["images"]),
        errors=tuple(_errors(pipe.events)),
    )

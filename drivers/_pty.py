"""A pseudo-terminal pair made by socat: two connected serial ports without hardware.

The twin opens :attr:`PtyPair.twin_port`; a client (driver, pyvisa, mbpoll) opens
:attr:`PtyPair.client_port`. Both are the resolved ``/dev/pts/N`` names.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import tempfile
import time

log = logging.getLogger(__name__)


class PtyUnavailable(RuntimeError):
    """socat is missing or did not create the pair in time."""


class PtyPair:
    """``socat pty,raw,echo=0 pty,raw,echo=0`` as a managed child process."""

    def __init__(self, timeout_s: float = 5.0) -> None:
        socat = shutil.which("socat")
        if socat is None:
            raise PtyUnavailable("socat not found on PATH (Debian package 'socat')")
        self._dir = tempfile.mkdtemp(prefix="ptypair-")
        twin_link = os.path.join(self._dir, "twin")
        client_link = os.path.join(self._dir, "client")
        self._proc = subprocess.Popen(
            [socat, "-d", "-d", f"pty,raw,echo=0,link={twin_link}",
             f"pty,raw,echo=0,link={client_link}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + timeout_s
        while not (os.path.exists(twin_link) and os.path.exists(client_link)):
            if self._proc.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise PtyUnavailable("socat did not create the pseudo-terminal pair")
            time.sleep(0.01)
        self.twin_port = os.path.realpath(twin_link)
        self.client_port = os.path.realpath(client_link)
        log.debug("pty pair twin=%s client=%s (socat pid %d)", self.twin_port,
                  self.client_port, self._proc.pid)

    def close(self) -> None:
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self) -> PtyPair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

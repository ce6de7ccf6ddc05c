"""The live page's words (``bench watch``, decision 0067), by code.

``WARNING``: the warnings the page lists (:class:`bench.watch.snapshot.PageWarning`) other
than the plan's identifiability warnings and the log's lines, which it shows as they were
written.  ``MESSAGE``: its message of a run it cannot show yet, or of a fit that failed
(:class:`bench.watch.snapshot.PageMessage`).  ``ERROR``: the server's answer to a request it
refuses (:class:`bench.watch.server.PageError`).
"""

from __future__ import annotations

from . import Words, say

WARNING: Words = {
    "force_not_reached": lambda key, target_N, error, iterations: (f"{key}: force {target_N:g} N not reached "
                                                                   f"(error {100 * error:+.1f} %, {iterations} "
                                                                   "iterations)"),
}


def warning(code: str, fields) -> str:
    """A warning of the page in words."""
    return say(WARNING, code, fields)


# the page's message of a run it cannot show yet, and of a fit that failed
# (bench.watch.snapshot.PageMessage)
MESSAGE: Words = {
    "waiting": lambda: "no run.json yet: waiting for the run to start",
    "unreadable": lambda error: f"run.json: {error}",
    "too_deep": lambda: "run.json: nested too deeply",
    "fit_failed": lambda names: (f"the final fit failed: {', '.join(names)} came out not finite or absurd (an overflow "
                                 "in the fit)"),
    "unusable": lambda: "unusable result",
}


# why the page's server answers a request with an error (bench.watch.server.PageError)
ERROR: Words = {
    "no_token": lambda: "this link has no token: open the link with ?token=... that `bench watch` or `bench run --watch` printed",
    "wrong_token": lambda: ("this link's token is not this server's (the page was restarted?): open the link "
                            "that `bench watch` or `bench run --watch` printed last"),
    "busy": lambda connections: f"{connections} connections busy; only a stop request is served now",
    "chunked": lambda: "Transfer-Encoding is not supported",
    "bad_length": lambda given: f"bad Content-Length: {', '.join(given)[:40]!r}",
    "too_large": lambda length, most: f"request body of {length} bytes; at most {most}",
    "host": lambda: "unexpected Host header",
    "no_page": lambda path: f"no such page: {path}",
    "no_action": lambda path: f"no such action: {path}",
    "stop_token": lambda: "a valid stop token is needed (the one printed with the page's URL)",
    "not_running": lambda status, gone: f"the run is not running ({'process gone' if gone else status})",
    "stop_unwritten": lambda error: f"could not write the stop request: {error}; use Ctrl-C in the run's terminal",
    "streams": lambda most: f"{most} live pages open already; close one",
}

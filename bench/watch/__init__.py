"""A live view of a run in the browser: ``bench watch RUN_DIR`` and ``bench run --watch``.

The page reads the run directory only (:mod:`.snapshot`), so it shows a run in this
process, in another one, a resumed run or a finished one; the server (:mod:`.server`,
standard library only) pushes changes as server-sent events and serves plotly's own
JavaScript from the installed package.  A stop from the page is a request file in the run
directory (:mod:`.stop`) that the running session turns into the Ctrl-C path.
"""

from .server import WatchServer, serve
from .stop import StopRequested, request_stop

__all__ = ["WatchServer", "serve", "StopRequested", "request_stop"]

"""A light, steady load beside a run: one process busy ``share`` of each 100 ms (default 0.3,
about 15 % of a 2-core machine), for timing `make test` "under light load" (issue 43).

    python -m benchtools.light_load [share] &   ...   kill %1
"""

import sys
import time


def main(share: float = 0.3, period_s: float = 0.1) -> None:
    while True:
        end = time.perf_counter() + share * period_s
        while time.perf_counter() < end:
            pass
        time.sleep((1 - share) * period_s)


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 0.3)

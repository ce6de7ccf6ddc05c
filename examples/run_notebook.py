"""Execute a notebook top to bottom in a fresh kernel (`make examples`); exit 1 naming the
cell that failed.  Usage: run_notebook.py NOTEBOOK WORKDIR"""

import sys
import time
from pathlib import Path

import nbclient
import nbformat


def main(notebook: str, workdir: str) -> int:
    nb = nbformat.read(notebook, as_version=4)
    t0 = time.monotonic()
    client = nbclient.NotebookClient(nb, timeout=900, kernel_name="python3",
                                     resources={"metadata": {"path": str(Path(workdir).resolve())}})
    try:
        client.execute()
    except nbclient.exceptions.CellExecutionError as e:
        print(f"{notebook}: a cell failed:\n{e}", file=sys.stderr)
        return 1
    out = Path(workdir) / Path(notebook).name
    nbformat.write(nb, out)
    n = sum(c.cell_type == "code" for c in nb.cells)
    print(f"{notebook}: {n} code cells executed in a fresh kernel in {time.monotonic() - t0:.0f} s; written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))

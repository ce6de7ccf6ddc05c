"""Reports: the run report (Markdown with PNG plots), the analysis page and the comparison
page (one HTML file each; the comparison's in ``_compare``, decision record 0026).

The data are prepared once (``_run.load_run`` reads a run directory into a typed record,
``_analysis.analysis_data`` reads an analysis dict), figures are drawn by three
modules (``_figures``: shared and the run report's; ``_figures_analysis``, ``_figures_modes``)
and rendered by one module per format (``_markdown``, ``_html``).
Decision record 0016.
"""

from ._compare import render_compare_html, write_compare_html
from ._damping import damping_row
from ._figures import plot_identification
from ._fundamentals import render_fundamentals_html, write_fundamentals_html
from ._html import render_analysis_html, write_analysis_html
from ._identification import ID_PARAMS, IdentificationData, analysis_estimate, identification_data
from ._markdown import write_report
from ._modes import COLUMNS as MODES_COLUMNS
from ._modes import RunModes, run_modes, write_modes
from ._modes import write_csv as write_modes_csv
from ._run import RunData, load_run
from ._sequence import sequence_md
from ._steps import UNSETTLED_RESIDUAL, residual_ratio

__all__ = ["ID_PARAMS", "UNSETTLED_RESIDUAL", "IdentificationData", "MODES_COLUMNS", "RunData", "RunModes", "analysis_estimate", "damping_row", "identification_data", "load_run",
           "plot_identification", "render_analysis_html", "render_compare_html", "render_fundamentals_html", "residual_ratio", "run_modes", "sequence_md", "write_analysis_html",
           "write_compare_html", "write_fundamentals_html", "write_modes", "write_modes_csv", "write_report"]

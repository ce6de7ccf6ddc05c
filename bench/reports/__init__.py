"""Reports: the run report (Markdown with PNG plots) and the analysis page (one HTML file).

The data are prepared once (``_run.load_run`` reads a run directory into a typed record,
``_analysis.analysis_data`` reads an analysis dict), figures are drawn in one module
(``_figures``) and rendered by one module per format (``_markdown``, ``_html``).
Decision record 0016.
"""

from ._figures import plot_identification
from ._html import render_analysis_html, write_analysis_html
from ._identification import ID_PARAMS, IdentificationData, identification_data
from ._markdown import write_report
from ._run import RunData, load_run
from ._steps import UNSETTLED_RESIDUAL, residual_ratio

__all__ = ["ID_PARAMS", "UNSETTLED_RESIDUAL", "IdentificationData", "RunData", "identification_data", "load_run",
           "plot_identification", "render_analysis_html", "residual_ratio", "write_analysis_html", "write_report"]

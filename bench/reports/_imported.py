"""The report of an imported run (``bench import``, decision record 0081): what the file was,
where it came from and what it holds, never a bench measurement."""

from __future__ import annotations

from ..frf_import import origin_of

_RESPONSE = {"disp": "compliance X/F", "vel": "mobility V/F", "accel": "accelerance A/F"}
_LEVEL = {"force": "force-controlled: the force amplitude held at each level (N)",
          "disp": "response-controlled: the displacement amplitude held at each level (m)",
          "accel": "response-controlled: the acceleration amplitude held at each level (m/s^2)"}


def imported(run) -> dict | None:
    """run.json's ``origin`` of an imported run, else None."""
    return origin_of(run.meta)


def header_md(run, origin: dict, table) -> list[str]:
    """The report's first lines for an imported run: imported from FILE, not a bench measurement."""
    plan = run.plan
    n_levels = len(plan.get("levels_N") or [])
    mapping = origin.get("mapping_file") or "none"
    md = [f"# Imported frequency responses: {origin.get('name', '?')}", "",
          f"**Imported from `{origin.get('file', '?')}`**: frequency responses measured by other software, "
          "**not a bench measurement**. Each step holds the response fundamental only (no time records, no "
          "harmonics): compliance_pp is |X1/F1|, and the bench's step-quality checks, force control, THD and "
          "noise do not apply.", ""]
    md += table(["", ""], [
        ["imported from", f"`{origin.get('file', '?')}`"],
        ["SHA-256", f"`{origin.get('sha256', '?')}`"],
        ["format", origin.get("format", "?")],
        ["mapping", f"`{mapping}`" if mapping != "none" else "none"],
        ["frequency response", _RESPONSE.get(origin.get("response", ""), "?") + " (stored as X1/F1 and A1/F1)"],
        ["levels", _LEVEL.get(origin.get("level_kind", ""), "?")],
        ["force beside the response", "yes (the energy balance uses it)" if origin.get("force")
         else "no: the amplitudes follow from the level (no energy balance)"],
        ["run directory", f"`{run.path}`"],
        [f"levels ({run.level_quantity.name}, {run.level_quantity.unit})",
         ", ".join(f"{v:g}" for v in run.levels_N)],
        ["points", f"{len(run.results)} over {n_levels} levels, {len(plan.get('freqs_Hz', []))} distinct "
                   f"frequencies from {min(plan.get('freqs_Hz', [float('nan')])):g} to "
                   f"{max(plan.get('freqs_Hz', [float('nan')])):g} Hz"],
        ["imported (UTC)", str(run.meta.get("started", "?"))],
    ])
    md += [""]
    return md


def steps_md(analysis: dict | None = None) -> list[str]:
    """In place of the analysis, the identification and the steps needing attention: an import
    has fundamentals only, no control and no time records; the fit to fundamentals' verdict
    when ``bench analyze`` has written it (``analysis``: analysis.json's dict)."""
    fitted = isinstance(analysis, dict) and analysis.get("kind") == "fundamentals"
    said = (["The friction models fitted to the fundamentals (`bench analyze`, "
             "[analysis.html](../analysis/analysis.html), decision 0084):", ""]
            + [f"- {line}" for line in str(analysis.get("verdict", "")).splitlines()]  # type: ignore[union-attr]
            if fitted else
            ["Not made yet: `bench analyze RUN` fits the friction models to the fundamentals (decision 0084)."])
    return ["## Analysis and identification", "", *said, "",
            "`bench identify` refuses an imported run (no time records).", "",
            "## Steps needing attention", "",
            "None judged: imported fundamentals carry neither a control record nor time records to check "
            "(the source's own checks are the measuring software's).", ""]

"""Every figure rounded to what its interval supports (issue 19).  The expected texts are
worked by hand from the rule in sim/discrepancy/rounding.py (last digit at the second
significant digit of the half-width when it starts with 1 or 2, else at the first)."""

import math

import pytest

from sim.discrepancy.analysis import interval_text  # what the verdict uses
from sim.discrepancy.rounding import last_digit, percent_text, round_to_interval, value_text


@pytest.mark.parametrize("value, low, high, unit, text", [
    (159.1549, 158.65, 159.65, " Hz", "159.2 Hz (95 %: 158.7 to 159.7 Hz)"),         # half 0.5: tenths
    (159.1549, 158.9, 159.4, " Hz", "159.15 Hz (95 %: 158.90 to 159.40 Hz)"),       # half 0.25: hundredths
    (41.234, 37.1, 45.3, " N s/m", "41 N s/m (95 %: 37 to 45 N s/m)"),               # half 4.1: units
    (0.00123456, 0.00121, 0.00126, "", "0.001235 (95 %: 0.001210 to 0.001260)"),    # half 2.5e-5
    (12345.6, 12301.0, 12389.0, " N/m", "12350 N/m (95 %: 12300 to 12390 N/m)"),      # half 44: tens
    (9.87e-6, 9.41e-6, 1.033e-5, " m", "9.9e-06 m (95 %: 9.4e-06 to 1.03e-05 m)"),    # half 4.6e-7
])
def test_figures_carry_the_digits_their_interval_supports(value, low, high, unit, text):
    assert interval_text(value, low, high, unit) == text


def test_signed_values_and_figures_without_an_interval():
    assert interval_text(-0.0312, -0.0351, -0.0273, " %", signed=True) == "-0.031 % (95 %: -0.035 to -0.027 %)"
    assert interval_text(4.8e-3, 4.8e-3, 4.8e-3, " m/s") == "0.0048 m/s"       # exact: three digits at most
    assert value_text(159.1549, math.nan, math.nan, " Hz") == "159 Hz"
    assert last_digit(0.0, math.inf) is None
    assert round_to_interval(math.nan, 1.0, 2.0) == ("n/a", "1.0", "2.0")


def test_a_held_out_error_not_computed_is_said_in_words():
    """The selection's log line printed "held-out nan %" where the page says "not computed"."""
    assert percent_text(math.nan) == "not computed"
    assert percent_text(0.1234) == "12.34 %"

"""The SCPI twin's instrument behaviour, checked against the SCPI/Keysight conventions."""

import pytest

from drivers._scpi_twin_model import ERROR_QUEUE_DEPTH, ScpiGeneratorModel

pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def model(rig):
    return ScpiGeneratorModel(rig)


def errors(model):
    out = []
    while (reply := model.execute("SYST:ERR?")) != '+0,"No error"':
        out.append(int(reply.split(",")[0]))
    return out


@pytest.mark.parametrize("command", ["FREQ 250", "FREQuency 250", "freq 250", "frequency 250",
                                     "SOUR:FREQ 250", ":source1:frequency:cw 250"])
def test_short_and_long_header_forms_are_equivalent_and_case_insensitive(model, command):
    model.execute(command)
    assert float(model.execute("FREQ?")) == 250.0
    assert errors(model) == []


def test_compound_message_answers_every_query_in_order(model):
    reply = model.execute("FREQ 10;VOLT 0.5;:FREQ?;VOLT?;:OUTP?")
    assert [float(x) for x in reply.split(";")] == [10.0, 0.5, 0.0]


def test_relative_header_after_semicolon_uses_previous_path(model):
    model.execute("VOLT:LIM:HIGH 2;LOW -1")
    assert float(model.execute("VOLT:LIM:LOW?")) == -1.0
    assert errors(model) == []


def test_unknown_header_queues_minus_113_and_the_rest_of_the_message_runs(model):
    assert model.execute("FOO:BAR 1;FREQ 77;:FREQ?") == "+7.70000000000000E+01"
    assert errors(model) == [-113]


def test_out_of_range_value_is_clipped_and_reported_minus_222(model):
    model.execute("FREQ 1e12")
    assert float(model.execute("FREQ?")) == 20e6
    assert errors(model) == [-222]


def test_error_queue_is_fifo(model):
    model.execute("BAD1")
    model.execute("FREQ -5")
    assert errors(model) == [-113, -222]


def test_error_queue_overflow_replaces_last_entry_with_minus_350(model):
    for _ in range(ERROR_QUEUE_DEPTH + 5):
        model.execute("NOPE")
    codes = errors(model)
    assert len(codes) == ERROR_QUEUE_DEPTH
    assert codes[:-1] == [-113] * (ERROR_QUEUE_DEPTH - 1)
    assert codes[-1] == -350


def test_cls_clears_the_error_queue(model):
    model.execute("NOPE")
    model.execute("*CLS")
    assert model.execute("SYST:ERR?") == '+0,"No error"'


def test_rst_restores_defaults_and_switches_output_off(model, rig):
    model.execute("FREQ 55;VOLT 1;:OUTP ON")
    model.execute("*RST")
    assert model.execute("FREQ?;VOLT?;:OUTP?") == \
        "+1.00000000000000E+03;+1.00000000000000E-01;0"
    assert rig.output_on is False


def test_every_setting_can_be_queried(model):
    queries = ["*IDN?", "*OPC?", "FUNC?", "FREQ?", "VOLT?", "VOLT:OFFS?", "VOLT:UNIT?",
               "VOLT:LIM:HIGH?", "VOLT:LIM:LOW?", "VOLT:LIM:STAT?", "VOLT:RANG:AUTO?",
               "OUTP?", "OUTP:LOAD?"]
    replies = [model.execute(q) for q in queries]
    assert all(r for r in replies)
    assert errors(model) == []


def test_high_impedance_load_doubles_displayed_voltage_but_not_the_output(model, rig):
    model.execute("VOLT 1")
    before = rig.amplitude_Vpp
    model.execute("OUTP:LOAD INF")
    assert float(model.execute("VOLT?")) == pytest.approx(2.0)
    assert rig.amplitude_Vpp == pytest.approx(before) == pytest.approx(2.0)


def test_settings_reach_the_plant(model, rig):
    model.execute("OUTP:LOAD INF;:FREQ 321;VOLT 0.4;VOLT:OFFS 0.1;:OUTP ON")
    assert (rig.freq_Hz, rig.amplitude_Vpp, rig.offset_V, rig.output_on) == \
        (321.0, pytest.approx(0.4), pytest.approx(0.1), True)


def test_voltage_clamp_limits_amplitude_with_settings_conflict(model):
    model.execute("OUTP:LOAD INF;:VOLT 1;VOLT:LIM:HIGH 1;LOW -1;STAT ON")
    model.execute("VOLT 5")
    assert float(model.execute("VOLT?")) == pytest.approx(2.0)
    assert errors(model) == [-221]


def test_missing_parameter_and_bad_number_are_reported(model):
    model.execute("FREQ")
    model.execute("FREQ abc")
    assert errors(model) == [-109, -104]


def test_unterminated_query_is_reported_minus_420(model):
    model.unterminated_query("FREQ?")
    assert errors(model) == [-420]

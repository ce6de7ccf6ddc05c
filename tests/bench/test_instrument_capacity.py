"""Every plan value a procedure turns into a block is checked against what the DAQ can
record before anything is switched on (issue 30 item 1, decision record 0050).

On main, ``dwell_cycles = 50000`` passed ``bench dry-run`` and the run failed at the dwell
with an internal error (block length 18300000 outside 1 .. 2^24-1 samples) after the output
had been on; ``bench resume`` switched it on again and failed the same way.  A block below
2^24 but above 436900 samples (``dwell_cycles = 3000`` on a 30-300 Hz grid) failed too, as
an instrument error: the block header counts at most 65535 data frames of 20 values.
"""

from __future__ import annotations

import textwrap
from dataclasses import replace

import pytest

from bench.cli import main
from bench.config import ConfigError, parse_plan, parse_rig, read_toml
from bench.storage import RunStore
from benchtools.plans import FAST
from benchtools.procs import bench_done, rig_toml_for
from drivers import MAX_BLOCK_SAMPLES, ScpiFunctionGenerator, plan_block, start_twins
from drivers._scpi_twin_model import GeneratorState
from sim.rig import RigModel, SimulatedRig

GRID = {"start_Hz": 30.0, "stop_Hz": 300.0, "points": 12}
CONTROL = FAST        # the fast steps of benchtools.plans


def dwell_plan(dwell_cycles: int, **control) -> dict:
    return {"plan": {"name": "long dwell", "levels_N": [1.0], "frequencies": dict(GRID),
                     "control": CONTROL | control,
                     "resonance": {"refine": True, "modes": ["feed"], "max_steps": 2, "dwell_cycles": dwell_cycles}}}


def plan_text(dwell_cycles: int) -> str:
    return textwrap.dedent(f"""\
        [plan]
        name = "long dwell"
        levels_N = [1.0]
        [plan.frequencies]
        start_Hz = 30.0
        stop_Hz = 300.0
        points = 12
        [plan.control]
        settle_cycles = 4
        min_settle_s = 0.0
        measure_cycles = 4
        control_cycles = 2
        ramp_s = 0.0
        [plan.resonance]
        refine = true
        modes = ["feed"]
        max_steps = 2
        dwell_cycles = {dwell_cycles}
        """)


def largest_said(message: str) -> int:
    return int(message.split("the largest that fits: ")[1].split()[0])


def test_the_largest_block_is_what_the_block_header_can_carry():
    """Independent fact, daq.dbc: NFrames is 16 bits, a data frame holds 20 values of the
    three channels; a longer block is refused by the driver before anything is sent."""
    import can

    from drivers import Channel, ChannelSpec
    from drivers._daq import CanFdDaq
    from drivers._daq_codec import database
    header = database().get_message_by_name("DAQ_BlockHeader")
    assert header.get_signal_by_name("NFrames").maximum == 65535
    assert MAX_BLOCK_SAMPLES == 65535 * 20 // 3 == 436900
    channels = tuple(ChannelSpec(c, 1.0, "V") for c in (Channel.FORCE, Channel.ACCELERATION, Channel.DISPLACEMENT))
    with can.Bus(interface="virtual", channel="capacity-test", fd=True) as bus:
        with pytest.raises(ValueError, match=r"block length 436901 outside 1 \.\. 436900 samples"):
            CanFdDaq(bus, channels).configure(25600.0, MAX_BLOCK_SAMPLES + 1)


@pytest.mark.parametrize("rate", [25600.0, 51200.0, 102400.0])
def test_the_largest_dwell_said_is_the_largest_block_the_daq_takes(rate):
    """Independent fact: the DAQ driver's own block plan at the grid's lowest frequency (a
    dwell's frequency is chosen online, anywhere in the grid): the value the refusal names
    fits, one more does not."""
    with pytest.raises(ConfigError, match=r"\[plan.resonance\] dwell_cycles: 50000 cycles at 30 Hz") as e:
        parse_plan(dwell_plan(50000, min_sample_rate_Hz=rate, harmonics=3))
    largest = largest_said(str(e.value))
    assert plan_block(30.0, largest, rate)[1] <= MAX_BLOCK_SAMPLES < plan_block(30.0, largest + 1, rate)[1]
    assert parse_plan(dwell_plan(largest, min_sample_rate_Hz=rate, harmonics=3)).dwell_cycles == largest


def test_every_block_value_is_named_with_its_key_and_the_largest_that_fits():
    with pytest.raises(ConfigError) as e:
        parse_plan(dwell_plan(10, measure_cycles=30000, control_cycles=30000, min_measure_s=1000.0))
    lines = str(e.value).splitlines()
    assert len(lines) == 3, lines
    for key, unit in (("measure_cycles", "cycles"), ("control_cycles", "cycles"), ("min_measure_s", "s")):
        line = next(ln for ln in lines if f"[plan.control] {key}: " in ln)
        assert "the DAQ's largest block is 436900 samples" in line and line.endswith(unit)
    # min_measure_s: the largest said fits at every frequency of the grid and between
    said = float(next(ln for ln in lines if "min_measure_s" in ln).split("fits: ")[1].split()[0])
    f = parse_plan(dwell_plan(10, min_measure_s=said))
    for fr in [*f.freqs_Hz, *(30.0 + k * 0.01 for k in range(27001))]:
        periods = max(4, -(-said * fr // 1))
        assert plan_block(fr, int(periods), 25600.0)[1] <= MAX_BLOCK_SAMPLES
    # steps: the grid, the refinement budget and the dwells within a plan's 50000; the
    # refinement keys number the levels in two digits (L00-L99); 720 + 60 x (820 + 1) = 49980
    # steps
    many = dwell_plan(10)
    many["plan"]["resonance"]["max_steps"], many["plan"]["levels_N"] = 999, [1.0] * 60
    with pytest.raises(ConfigError, match=r"\[plan.resonance\] max_steps: 999 steps per mode and level make 60720 "
                       r"steps .* the largest that fits: 820 steps per mode and level"):
        parse_plan(many)
    many["plan"]["resonance"]["max_steps"], many["plan"]["levels_N"] = 2, [1.0] * 101
    with pytest.raises(ConfigError, match=r"\[plan\] levels: 101 levels; a refined plan .* at most 100"):
        parse_plan(many)
    # the phase-resonance loop: a block after a change is up to 6 x block_periods
    with pytest.raises(ConfigError, match=r"\[plan.backbone\] block_periods: 1000 cycles .* the largest that fits: 14 cycles"):
        parse_plan({"plan": {"procedure": "phase_resonance", "levels_N": [1.0], "control": {"min_sample_rate_Hz": 102400,
                    "harmonics": 3}, "backbone": {"start_Hz": 80.0, "min_Hz": 20.0, "max_Hz": 160.0,
                                                  "block_periods": 1000}}})


@pytest.mark.timeout(120)
def test_dry_run_run_and_resume_refuse_a_dwell_the_daq_cannot_record_before_switching_on(tmp_path, capsys):
    """`bench run` and `bench resume` in real processes against twins held by the test
    (dry-run in this one, on them and on the simulated rig): exit 2, one line naming
    [plan.resonance] dwell_cycles, its unit and the largest that fits; the generator never
    touched (its state as at power-on), no run directory made, a stored run not resumed."""
    with start_twins(SimulatedRig(RigModel(seed=3))) as twins:
        rig = tmp_path / "rig.toml"
        rig.write_text(rig_toml_for(twins))
        plan = tmp_path / "plan.toml"
        plan.write_text(plan_text(50000))
        out = tmp_path / "run"

        def bench(*args: str) -> tuple[int, list[str]]:
            p = bench_done(*args, timeout=60)
            return p.returncode, [ln for ln in p.stderr.splitlines() if ln.strip()]

        def said(err: list[str]) -> None:
            assert len(err) == 1 and "[plan.resonance] dwell_cycles: 50000 cycles" in err[0], err
            assert "the largest that fits: 511 cycles" in err[0] and "Traceback" not in err[0]

        for rig_args in (["--rig", str(rig)], []):         # the twins' rig, the simulated rig
            assert main(["dry-run", "--plan", str(plan), *rig_args]) == 2
            said(capsys.readouterr().err.splitlines())
        rc, err = bench("run", "--out", str(out), "--no-report", "--plan", str(plan), "--rig", str(rig))
        assert rc == 2
        said(err)
        assert not out.exists()
        assert twins.generator.state == GeneratorState()       # never configured, never on

        # a run an earlier version started with that plan (it was accepted then)
        stored = replace(parse_plan(dwell_plan(100)), dwell_cycles=50000)
        store = RunStore.create(out, {"plan": stored.to_dict(), "sim_seed": None,
                                      "rig": parse_rig(read_toml(rig), str(rig)).to_dict()})
        store.update(status="interrupted")
        rc, err = bench("resume", str(out))
        assert rc == 2
        said(err)
        assert [e["event"] for e in RunStore(out).events()] == ["start"]      # no resume, no output_off
        assert not list((out / "steps").iterdir())
        assert twins.generator.state == GeneratorState()
        with ScpiFunctionGenerator(twins.generator_url) as gen:
            assert gen.output_enabled() is False

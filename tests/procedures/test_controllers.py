"""The stepped-sine loop is shared (issue 31 item 1, decision 0052): a fourth, trivial
controller, a constant-voltage sweep, in a few dozen lines, runs end to end on the
simulated rig behind the real safety supervisor with the loop's ramps, settling,
measurement and records unchanged; and the controllers' outcomes are typed (a level out of
the drive's reach is a reason code, not a word in a message)."""

from __future__ import annotations

import math

import pytest

from bench.studies.montecarlo import PlantDaq, PlantGenerator
from procedures.control import ControlFields, Outcome, Reason, ResponseControl
from procedures.kind import Quantity
from procedures.safety import SupervisedDaq, SupervisedGenerator, Supervisor
from procedures.stepped_sine import ForceUnreachable, SteppedSine
from sim.rig import SimulatedRig
from tests.procedures.test_force_control import DEMO, RIG, Daq, Generator, run

VOLTAGE = Quantity("drive", "drive amplitude", "V", "U")


class ConstantVoltage:
    """Each level is the generator's amplitude in V (= Vpp / 2): drive it and measure; no
    iteration, so the force is whatever the rig takes (an open-loop stepped sine)."""

    quantity = VOLTAGE

    def first_vpp(self, proc, step, new_sweep):
        return min(2 * step.force_N, proc.max_vpp)

    def control(self, proc, step):
        proc.history = [(proc.drive.amplitude_Vpp, math.nan)]
        return Outcome(0.0, 0, Reason.WITHIN)

    def fields(self, step, measured, outcome):
        return ControlFields(target_force_N=measured["force_N"], force_error=0.0, force_converged=True)


def test_a_constant_voltage_sweep_is_a_controller_on_the_same_loop():
    from bench.config import parse_plan
    plan = parse_plan({"plan": {"levels_N": [0.1, 0.2], "control": dict(DEMO["control"]),
                                "frequencies": {"list_Hz": [60.0, 200.0]}}})
    plant = SimulatedRig(RIG.model)
    gen = Generator(plant)
    sup = Supervisor(RIG.limits, gen)
    proc = SteppedSine(plan, SupervisedGenerator(gen, sup), SupervisedDaq(Daq(plant), sup),
                       amp_gain_N_per_V=RIG.amp_gain_N_per_V, drive_limit_V=RIG.limits.drive_V,
                       controller=ConstantVoltage())
    proc.disp_noise_floor_m = 2e-9
    results = []
    proc.run(set(), lambda step, res, raw: results.append(res))
    assert [(r["level_index"], r["freq_Hz"]) for r in results] == [(0, 60.0), (0, 200.0), (1, 60.0), (1, 200.0)]
    for r, level in zip(results, (0.1, 0.1, 0.2, 0.2)):
        assert r["drive_Vpp"] == pytest.approx(2 * level, rel=1e-9)      # the level held, open loop
        assert r["control_iterations"] == 0 and r["target_force_N"] == r["force_N"] > 0
    # the force per volt the rig took at 200 Hz, through the shaker: the same at both levels
    # within a few per cent (a linear amplifier), an independent check that each was driven
    k = [r["force_N"] / (r["drive_Vpp"] / 2) for r in results if r["freq_Hz"] == 200.0]
    assert k[1] == pytest.approx(k[0], rel=0.05)
    assert plant.gen.output_on is False              # the loop's stop: ramped down, output off


def test_an_unreachable_level_is_a_reason_code_not_a_word():
    """The loop refuses the step on the code: a controller whose message says nothing of
    "unreachable" still stops the run as the plan says (infeasible = "refuse")."""
    class Short(ConstantVoltage):
        def control(self, proc, step):
            return Outcome(-0.5, 1, Reason.UNREACHABLE, "level beyond the amplifier")
    from bench.config import parse_plan
    plan = parse_plan({"plan": {"levels_N": [0.1], "control": dict(DEMO["control"]),
                                "frequencies": {"list_Hz": [60.0]}}})
    plant = SimulatedRig(RIG.model)
    proc = SteppedSine(plan, PlantGenerator(plant), PlantDaq(plant), amp_gain_N_per_V=RIG.amp_gain_N_per_V,
                       controller=Short())
    with pytest.raises(ForceUnreachable, match="level beyond the amplifier"):
        proc.run(set(), lambda *a: None)


def test_the_response_controller_states_its_quantity_and_records_it():
    rc = ResponseControl("accel", mass_kg=10.0, tolerance=0.02)
    assert (rc.quantity.name, rc.quantity.unit) == ("acceleration", "m/s^2")
    # the force controller's unreachable step names the drive limit as before
    results, skipped, _, _, _ = run([30.0], [1000.0], drive_V=0.5, infeasible="skip")
    assert not results and "unreachable" in skipped[0][1] and "drive limit" in skipped[0][1]


@pytest.mark.parametrize("ask", ["choose", "refine"])
def test_phase_resonance_is_the_same_loop_and_refuses_a_grid_it_does_not_have(ask):
    """Phase resonance is the phase's controller and a schedule on the one loop (decision
    0060), built by the one factory; the loop's adaptive choice and refinement pick points
    of a frequency grid it has not got: asked for either, it says so before the drive is
    touched, never ignores it."""
    from bench.config import parse_plan
    from procedures.factory import procedure_for
    from procedures.kind import PHASE
    plan = parse_plan({"plan": {"procedure": "phase_resonance", "levels_N": [0.1], "backbone": {"start_Hz": 80.0},
                                "control": dict(DEMO["control"])}})
    plant = SimulatedRig(RIG.model)
    proc = procedure_for(plan, PlantGenerator(plant), PlantDaq(plant), amp_gain_N_per_V=RIG.amp_gain_N_per_V,
                         mass_kg=10.0)
    assert type(proc) is SteppedSine and proc.controller.quantity is PHASE
    picks = {"choose": lambda sweep: sweep, "refine": lambda step: None}
    with pytest.raises(ValueError, match=f"phase resonance: the controller finds each point's frequency.*"
                                         f"{'adaptive choice' if ask == 'choose' else 'resonance refinement'}"):
        proc.run(set(), lambda *a: None, **{ask: picks[ask]})
    assert plant.gen.output_on is False and proc.drive.on is False

"""What one fit of a robot reads: its ports, coordinate stage, error budget and product limits.

A :class:`FitContext` is made once per fit attempt (:meth:`FitContext.for_robot`) and handed to
every step of the fitter (structure search, format choice, lowering), so that none of them
re-derives it from the robot description.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .cost import DEFAULT_COST_MODEL, CostModel
from .features import coordinate_stage
from ..constraints.devices import FAMILIES
from .plan import PlanInput
from .ports import plan_inputs

__all__ = ["FitError", "FormatError", "Budget", "FitContext", "operand_bits"]


class FitError(RuntimeError):
    """No plan meets the robot's tolerance."""


class FormatError(FitError):
    """No fixed-point format keeps the rounding error within the quantization budget."""


@dataclass(frozen=True)
class Budget:
    """The tolerance (pu) split into output rounding, certified quantization and approximation,
    with a 15 % margin."""
    tolerance: float
    rounding: float
    quantization: float
    approximation: float

    @classmethod
    def split(cls, tolerance: float, ticks_per_pu: float, quantization_share: float = 0.1) -> "Budget":
        rounding = 0.5 / ticks_per_pu
        quant = quantization_share * tolerance
        approx = tolerance - rounding - quant - 0.15 * tolerance
        if approx <= 0:
            raise FitError(f"tolerance {tolerance:g} pu leaves no approximation budget after "
                           f"output rounding ({rounding:g} pu); raise hardware.clock_hz or the tolerance")
        return cls(tolerance, rounding, quant, approx)


def operand_bits(robot) -> tuple[int, int] | None:
    """The signed operand widths every plan multiplication must fit: those of the DSP block
    of ``hardware.dsp`` when ``fit.products = "dsp"``; else None (exact products)."""
    if robot.fit.products != "dsp" or robot.hardware.dsp not in FAMILIES:
        return None
    return FAMILIES[robot.hardware.dsp].dsp


@dataclass(frozen=True)
class FitContext:
    """The fixed inputs of one fit attempt.

    Attributes
    ----------
    robot : ikseries.robot.Robot
        The robot description (reference IK, calibration, workspace, fit options).
    inputs : tuple of PlanInput
        Port formats of the plan (:func:`ikseries.fit.ports.plan_inputs`).
    stage : CylindricalStage or CartesianStage
        The coordinate stage shared by every servo.
    budget : Budget
        The error budget of this attempt.
    operand_bits : (int, int) or None
        Product operand limit of the plan builder (``fit.products = "dsp"``).
    mixed : bool
        ``fit.lowering = "mixed"``: the Horner/Estrin mix of least depth, else nested Horner.
    cost_model : CostModel
        What a servo's structure costs (:mod:`ikseries.fit.cost`); the fit keeps the cheapest.
    structure_costs : dict
        The costs priced so far (:func:`ikseries.fit.lowering.structure_cost`: a trial plan
        each; servos of one leg try the same structures).
    trial_builders : dict
        Per (feature bits, lowering) a plan builder holding the coordinate stage, on which
        :func:`ikseries.fit.lowering.trial_plan` builds one servo's plan at a time.
    format_hints : dict
        Per servo the feature precision of the last fit priced with its coefficients
        (:func:`ikseries.fit.formats.fitted_cost`), tried first for the next.
    """
    robot: object
    inputs: tuple[PlanInput, ...]
    stage: object
    budget: Budget
    operand_bits: tuple[int, int] | None
    mixed: bool
    cost_model: CostModel = DEFAULT_COST_MODEL
    structure_costs: dict = field(default_factory=dict, compare=False, repr=False)
    trial_builders: dict = field(default_factory=dict, compare=False, repr=False)
    format_hints: dict = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def for_robot(cls, robot, quantization_share: float, cost_model: CostModel = DEFAULT_COST_MODEL
                  ) -> "FitContext":
        """The context of ``robot`` with ``quantization_share`` of the tolerance for rounding,
        choosing structures by ``cost_model``."""
        budget = Budget.split(robot.fit.tolerance_pu, robot.ticks_per_pu, quantization_share)
        mixed = robot.fit.lowering == "mixed"
        # cos/sin error e moves the tip by up to R_max * e; keep that to ~1 % of the budget
        rmax = max(abs(robot.workspace.inputs[0].min), abs(robot.workspace.inputs[0].max))
        stage = coordinate_stage(robot, trig_tol=min(1e-4, 2e-5 * 40.0 / max(rmax, 1e-9)), table=mixed)
        return cls(robot, tuple(plan_inputs(robot)), stage, budget, operand_bits(robot), mixed, cost_model)

    @property
    def ticks_per_pu(self) -> float:
        return self.robot.ticks_per_pu

"""``softplan run``'s loaded arm: the options that give the arm a weight and a tip load (the
arm then plans as :class:`~softplan_jax.rod.RodModel`, see the documentation's page "The loaded
arm"), the model they and a scenario file's ``arm.material`` block make, and its summary rows."""

from __future__ import annotations

from .common import InputError

__all__ = ["add_gravity_options", "resolve_model", "model_report", "model_rows"]

# A rubber-like rod's torsional stiffness: GJ = EI / (1 + nu) with Poisson's ratio nu = 0.5.
DEFAULT_TORSION_RATIO = 1.0 / 1.5


def add_gravity_options(run) -> None:
    """The loaded arm's options (one argument group)."""
    g = run.add_argument_group("the loaded arm: gravity and a tip load (see the documentation's page 'The loaded arm')")
    g.add_argument("--weight", type=float, default=None, metavar="W",
                   help="the arm's weight per unit length, >= 0 N/m, gravity along -z: plan for the loaded arm "
                   "(needs --stiffness, or a scenario file whose arm has a 'material' block)")
    g.add_argument("--stiffness", type=float, default=None, metavar="EI",
                   help="bending stiffness EI, > 0 N m^2, of every segment")
    g.add_argument("--torsional-stiffness", type=float, default=None, metavar="GJ",
                   help="torsional stiffness GJ, > 0 N m^2 (default EI / 1.5: a rubber-like rod)")
    g.add_argument("--tip-load", default=None, metavar="FX,FY,FZ",
                   help="a dead force at the tip, N, e.g. a payload's weight 0,0,-0.5 (default none)")
    g.add_argument("--pcc", action="store_true",
                   help="plan with the PCC arm even where the scenario file has a 'material' block")


def _tip_load(text: str):
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3:
        raise InputError(f"--tip-load must be three numbers FX,FY,FZ, got {text!r}")
    return values


def resolve_model(args, scenario_path: str | None):
    """The arm model of a run: None (the PCC arm) or a RodModel from the options, over the scenario
    file's ``arm.material`` block where it has one. InputError for a bad or partial model."""
    from ..rod._model import RodModel
    from ..scenarios._material import load_material

    flags = (args.weight, args.stiffness, args.torsional_stiffness, args.tip_load)
    if args.pcc:
        if any(f is not None for f in flags):
            raise InputError("--pcc plans with the PCC arm: drop --weight, --stiffness, --torsional-stiffness "
                             "and --tip-load")
        return None
    try:
        base = load_material(scenario_path) if scenario_path is not None else None
    except ValueError as err:
        raise InputError(str(err)) from None
    if base is None and all(f is None for f in flags):
        return None
    if base is None and (args.weight is None or args.stiffness is None):
        raise InputError("the loaded arm needs both --weight and --stiffness (or a scenario file whose arm has a "
                         "'material' block)")
    fields = {} if base is None else dict(
        bending_stiffness=base.bending_stiffness, torsional_stiffness=base.torsional_stiffness,
        weight_per_length=base.weight_per_length, tip_load=base.tip_load)
    if args.stiffness is not None:
        fields["bending_stiffness"] = args.stiffness
        fields.setdefault("torsional_stiffness", args.stiffness * DEFAULT_TORSION_RATIO)
    if args.torsional_stiffness is not None:
        fields["torsional_stiffness"] = args.torsional_stiffness
    if args.weight is not None:
        fields["weight_per_length"] = args.weight
    if args.tip_load is not None:
        fields["tip_load"] = _tip_load(args.tip_load)
    try:
        return RodModel(**fields)
    except ValueError as err:
        raise InputError(str(err)) from None


def model_report(model) -> dict:
    """The summary's ``arm_model`` entry: "pcc", or the loaded rod's material (lists per segment)."""
    from ..scenarios._material_block import material_to_dict

    if model is None:
        return {"kind": "pcc"}
    return {"kind": "loaded", **material_to_dict(model)}


def model_rows(s: dict) -> list:
    """The text summary's row of the arm model."""
    m = s["arm_model"]
    if m["kind"] == "pcc":
        return [("arm model", "PCC (piecewise constant curvature, paper §2.1)")]
    def fmt(x):
        return f"[{', '.join(f'{v:.4g}' for v in x)}]" if isinstance(x, list) else f"{x:.4g}"

    return [("arm model", f"loaded rod: EI {fmt(m['bending_stiffness'])} N m^2, GJ {fmt(m['torsional_stiffness'])} "
             f"N m^2, weight {fmt(m['weight_per_length'])} N/m, tip load {fmt(m['tip_load'])} N (gravity along -z)")]

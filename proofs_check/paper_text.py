"""Textual errata of the DRIP paper, re-verified against its LaTeX source.

These errata are about notation (a reference, an index, a symbol), so there is nothing to
compute: each check confirms that the source still says what ERRATA.md records (the check fails
if the source no longer contains it, i.e. the record is stale). The source is looked up at
``$DRIP_PAPER_TEX``, else ``shared/papers/drip_paper.tex`` beside the repository (where the
project keeps its shared folder); where it cannot be found the verdict is SKIP (not
re-verified, nothing claimed either way).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from proofs_check._core import CheckResult, Context, Verdict, register, result

_REPO = Path(__file__).resolve().parent.parent
_CANDIDATES = (
    _REPO.parent / "shared" / "papers" / "drip_paper.tex",
    _REPO / "shared" / "papers" / "drip_paper.tex",
)


def _source() -> str | None:
    env = os.environ.get("DRIP_PAPER_TEX")
    for path in [Path(env)] if env else list(_CANDIDATES):
        try:
            return path.read_text(encoding="utf-8")
        except OSError:
            continue
    return None


def _textual(name: str, label: str, erratum: str, patterns: list[str], what: str) -> CheckResult:
    src = _source()
    if src is None:
        return CheckResult(
            name=name,
            label=label,
            verdict=Verdict.SKIP,
            residual=float("nan"),
            erratum=erratum,
            detail=f"{what} (paper source not found: not re-verified; set DRIP_PAPER_TEX)",
        )
    flat = re.sub(r"\s+", " ", src)
    missing = [p for p in patterns if re.search(p, flat) is None]
    return result(
        name,
        label,
        holds=not missing,
        residual=float(len(missing)),
        erratum=erratum,
        detail=what if not missing else f"recorded text not found in the source: {missing}",
    )


@register("text.tasil_loss_index", "DRIP eq. (LossTaSIL)")
def check_loss_index(ctx: Context) -> CheckResult:
    """The TaSIL loss takes ``max_{s in partition}`` of ``||Psi_t||``: s is not used."""
    return _textual(
        "text.tasil_loss_index",
        "DRIP eq. (LossTaSIL)",
        "E2",
        [r"\\max_\{s \\in \\partition\{k\}\{T\}/\\\{T\\\}\} \\norm\{ \\Psi\^\{\\pi\^\\star\}_t"],
        "loss maximises over s but indexes Psi_t (and nabla_x Psi_t); read Psi_s",
    )


@register("text.uncertainty_ig_reference", "DRIP Sec. UncertaintyIG, first sentence")
def check_uncertainty_ref(ctx: Context) -> CheckResult:
    """The uncertainty-IG is said to be 'defined in (policy-IG)'."""
    return _textual(
        "text.uncertainty_ig_reference",
        "DRIP Sec. UncertaintyIG, first sentence",
        "E3",
        [
            r"uncertainty induced imitation gap \(uncertainty-IG\), defined in~\\eqref\{eqn:"
            r"Decomposition:IG:Policy\}"
        ],
        "uncertainty-IG referred to eqn:Decomposition:IG:Policy; should be ...:Uncertainty",
    )


@register("text.corollary_symbols", "DRIP text after Cor. 1 (corol:DiscreteDeltaISS)")
def check_corollary_symbols(ctx: Context) -> CheckResult:
    """The bound after the corollary uses kappa, lambda_kappa for theta, lambda_theta."""
    return _textual(
        "text.corollary_symbols",
        "DRIP text after Cor. 1 (corol:DiscreteDeltaISS)",
        "E6",
        [r"\\frac\{1\}\{\\sqrt\{\\kappa \\lambda_\\kappa\}\}"],
        "kappa, lambda_kappa are theta, lambda_theta of Prop. 1 (kappa is later the Markov radius)",
    )


@register("text.expert_ode", "DRIP eq. (ExpertProcess), (TaSILProcess)")
def check_expert_ode(ctx: Context) -> CheckResult:
    """The nominal ODEs are written ``d x_t = fbar(...)`` without ``dt`` (same family as E1)."""
    return _textual(
        "text.expert_ode",
        "DRIP eq. (ExpertProcess), (TaSILProcess)",
        "E1",
        [
            r"d\\xstart\{t\} = \\fbar\{t,\\xstart\{t\}, \\pistar\{\\xstart\{t\}\}\}, \\quad",
            r"y_t\^\\star = \\fbar\{t,y_t\^\\star, \\pistar\{y_t\^\\star\} \+ \\varsigma_t\}",
        ],
        "d x = fbar(...) without dt, and Prop. 1's y_t = fbar(...) without the derivative",
    )


@register("text.l1_noninteger_p", "DRIP Thm. L1DRAC (eqn:result:2)")
def check_noninteger_p(ctx: Context) -> CheckResult:
    """rho_L1 is evaluated at log sqrt(1/delta), an integer only for delta = e^{-2k}."""
    return _textual(
        "text.l1_noninteger_p",
        "DRIP Thm. L1DRAC (eqn:result:2)",
        "E9",
        [r"e \\cdot \\rho_\{\\mathcal\{L\}_1\}\\left\(\\log \\sqrt\{ \\frac\{1\}\{\\delta\} \}"],
        "rho_L1(p) exists for integer p only; the valid radius is l1drac.integer_p's",
    )

"""Human-readable reports: Markdown for certificates and validations, text for the L1 designer."""

from __future__ import annotations

import math
from typing import Any


def _f(x: Any, digits: int = 6) -> str:
    if x is None:
        return "n/a"
    if isinstance(x, str):
        return x
    if isinstance(x, bool):
        return "yes" if x else "no"
    x = float(x)
    if math.isnan(x):
        return "n/a"
    return f"{x:.{digits}g}"


def certificate_markdown(cert: Any) -> str:
    """Markdown rendering of a :class:`~drip_cert.bounds.certificate.Certificate`."""
    d = cert.to_dict()
    s = d["system"]
    lines = [f"# drip-cert certificate: {s['name']}", ""]
    verdict = "CERTIFIED" if d["certified"] else "NOT CERTIFIED"
    lines.append(f"**{verdict}** (n = {s['n']}, m = {s['m']}, d = {s['d']}, T = {s['horizon']:g})")
    if d["estimated_constants"]:
        lines.append("")
        lines.append("Constants that are sampled **estimates**, not bounds: "
                     + ", ".join(d["estimated_constants"])
                     + ". Give sound values in the spec's `[constants]` table to remove them.")
    lines += ["", "## Assumptions", "", "| id | holds | margin | how | detail |",
              "|---|---|---|---|---|"]
    for a in d["assumptions"]:
        lines.append(f"| {a['id']} | {_f(a['holds'])} | {_f(a['margin'])} | {a['how']} | "
                     f"{a['detail']} |")
    lines += ["", "## Constants", "", "| constant | value | how | source | note |",
              "|---|---|---|---|---|"]
    for name, q in d["constants"].items():
        lines.append(f"| {name} | {_f(q['value'])} | {q['how']} | {q['source']} | {q['note']} |")
    c = d["contraction"]
    lines += ["", "## Contraction (DRIP Assumption 2)", "",
              f"Euclidean rate lambda = {_f(c['rate'])} ({c['how']}, {c['method']}) on "
              f"{c['region']}; metric rate {_f(c['metric_rate'])}."]
    if c["learned"] is not None:
        lines.append(f"Learned closed loop: lambda = {_f(c['learned']['rate'])} "
                     f"({c['learned']['how']}, {c['learned']['method']}).")
    if d["delta_iss"] is not None:
        di = d["delta_iss"]
        lines += ["", "## delta-ISS gain (DRIP Proposition 1)", "",
                  f"gain used downstream {_f(di['gain'])} ({di['used']}); the paper's gain at the "
                  f"best theta = {_f(di['theta_star'])} is {_f(di['gain_paper'])}."]
    if d.get("tasil"):
        t = d["tasil"]
        lines += ["", "## TaSIL (policy-induced imitation gap)", "",
                  f"h0 = {_f(t.get('h0'))}, h1 = {_f(t.get('h1'))}, gamma0 = "
                  f"{_f(t.get('gamma0'))}, L_Delta = {_f(t.get('L_Delta'))}, deterministic gap "
                  f"bound {_f(t.get('gap_bound'))}, rho_TaSIL = {_f(t.get('rho'))} "
                  f"(delta = {_f(t.get('delta'))}, n = {t.get('n')}); vacuous forms: "
                  f"{', '.join(t.get('vacuous') or []) or 'none'}.",
                  "", f"_{t.get('label', '')}_"]
    if d.get("l1drac"):
        lines += ["", "## L1-DRAC design", "", l1_design_text(d["l1drac"])]
    r = d["rho"]
    lines += ["", "## Total", "",
              f"rho_TaSIL = {_f(r['rho_tasil'])}, rho_L1 = {_f(r['rho_l1'])}, "
              f"rho = {_f(r['rho_total'])} ({r['source']})"]
    if d["notes"]:
        lines += ["", "## Notes", ""] + [f"* {n}" for n in d["notes"]]
    return "\n".join(lines) + "\n"


def l1_design_text(rep: dict[str, Any]) -> str:
    """Text rendering of an L1-DRAC design report (the ``design-l1`` JSON)."""
    lines = [
        f"feasible: {_f(rep.get('feasible'))}",
        f"p = {rep.get('p')}, omega = {_f(rep.get('omega'))}, lambda_s = "
        f"{_f(rep.get('lambda_s'))}, T_s = {_f(rep.get('Ts'))}",
        f"rho_r = {_f(rep.get('rho_r'))}, rho_a = {_f(rep.get('rho_a'))}, rho = "
        f"{_f(rep.get('rho'))}, kappa = {_f(rep.get('kappa'))}",
        "",
        "| eq | lhs | rhs | margin | holds |",
        "|---|---|---|---|---|",
    ]
    for c in rep.get("conditions", []):
        lines.append(f"| ({c['eq']}) | {_f(c['lhs'])} | {_f(c['rhs'])} | {_f(c['margin'])} | "
                     f"{_f(c['holds'])} |")
    if rep.get("reason"):
        lines += ["", f"reason: {rep['reason']}"]
    return "\n".join(lines)


def validation_text(rep: dict[str, Any]) -> str:
    """Text rendering of a validation report."""
    lines = [f"validation: {'HOLDS' if rep.get('holds') else 'VIOLATED'}"
             + ("" if rep.get("at_certified_parameters", True)
                else " (NOT at certified parameters)"),
             "", "| check | bound | empirical | ci_high | ratio | holds |",
             "|---|---|---|---|---|---|"]
    for c in rep.get("checks", []):
        lines.append(f"| {c['name']} | {_f(c['bound'])} | {_f(c['empirical'])} | "
                     f"{_f(c['ci_high'])} | {_f(c['ratio'])} | {_f(c['holds'])} |")
    for note in rep.get("notes", []):
        lines.append(f"* {note}")
    return "\n".join(lines)

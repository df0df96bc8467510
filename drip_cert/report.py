"""Human-readable reports: Markdown for certificates and validations, text for the L1 designer."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.numerics.atomic_io import atomic_write_text


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
    verdict = {
        "certified": "CERTIFIED",
        "conditional": "CONDITIONAL",
        "not_certified": "NOT CERTIFIED",
    }[d["verdict"]]
    skipped = [
        k for k, v in d["parts"].items() if v["verdict"] in ("not_requested", "not_applicable")
    ]
    covers = [k for k in d["parts"] if k not in skipped]
    lines.append(
        f"**{verdict}**"
        + (
            f" for the parts computed ({', '.join(covers)}; not: {', '.join(skipped)})"
            if skipped
            else ""
        )
        + f" (n = {s['n']}, m = {s['m']}, d = {s['d']}, T = {s['horizon']:g})"
    )
    lines.append("")
    lines.append(
        "Parts: "
        + "; ".join(f"{k}: {v['verdict'].replace('_', ' ')}" for k, v in d["parts"].items())
        + "; rho = rho_TaSIL + rho_L1: "
        + ("certified" if d["rho"]["certified"] else "not certified (needs both parts)")
    )
    lines.extend(
        f"* {k} {v['verdict'].replace('_', ' ')}: {v['reasons'][0]}"
        for k, v in d["parts"].items()
        if v["verdict"] in ("not_requested", "not_applicable")
    )
    lines.extend(
        f"* {k} {v['verdict'].replace('_', ' ')}, binding condition: {v['binding']['text']}"
        for k, v in d["parts"].items()
        if v.get("binding")
    )
    lines.append("")
    if d["verdict"] == "certified":
        lines.append(
            "Every check holds, every input is exact, sound or given"
            + (f" (given: {', '.join(d['given_constants'])})" if d["given_constants"] else "")
            + ", and every region-limited result is used only where a proof covers it."
        )
    else:
        lines.append("What the verdict rests on:")
        lines.append("")
        lines.extend(f"* {r}" for r in d["verdict_reasons"])
    lines += _coordinate_lines(d["coordinates"], d["verdict"])
    if d["estimated_constants"]:
        lines.append("")
        lines.append(
            "Constants that are sampled **estimates**, not bounds: "
            + ", ".join(d["estimated_constants"])
            + ". Give sound values in the spec's `[constants]` table to remove them."
        )
    lines += [
        "",
        "## Assumptions",
        "",
        "| id | status | margin | how | scope | detail |",
        "|---|---|---|---|---|---|",
    ]
    for a in d["assumptions"]:
        scope = a["scope"] + (
            "" if a["scope_justified"] else f" (**not justified**: {a['scope_reason']})"
        )
        lines.append(
            f"| {a['id']} | {a['status']} | {_f(a['margin'])} | {a['how']} | {scope} | "
            f"{a['detail']} |"
        )
    lines += [
        "",
        "## Constants",
        "",
        "| constant | value | how | source | note |",
        "|---|---|---|---|---|",
    ]
    for name, q in d["constants"].items():
        lines.append(f"| {name} | {_f(q['value'])} | {q['how']} | {q['source']} | {q['note']} |")
    c = d["contraction"]
    lines += [
        "",
        "## Contraction (DRIP Assumption 2)",
        "",
        f"Euclidean rate lambda = {_f(c['rate'])} ({c['how']}, {c['method']}) on "
        f"{c['region']}; metric rate {_f(c['metric_rate'])}.",
    ]
    if c["learned"] is not None:
        lines.append(
            f"Learned closed loop: lambda = {_f(c['learned']['rate'])} "
            f"({c['learned']['how']}, {c['learned']['method']})."
        )
    if d["delta_iss"] is not None:
        di = d["delta_iss"]
        lines += [
            "",
            "## delta-ISS gain (DRIP Proposition 1)",
            "",
            f"gain used downstream {_f(di['gain'])} ({di['used']}); the paper's gain at the "
            f"best theta = {_f(di['theta_star'])} is {_f(di['gain_paper'])}.",
        ]
    if d.get("tasil"):
        t = d["tasil"]
        lines += [
            "",
            "## TaSIL (policy-induced imitation gap)",
            "",
            f"h0 = {_f(t.get('h0'))}, h1 = {_f(t.get('h1'))}, gamma0 = "
            f"{_f(t.get('gamma0'))}, L_Delta = {_f(t.get('L_Delta'))}, deterministic gap "
            f"bound {_f(t.get('gap_bound'))}, rho_TaSIL = {_f(t.get('rho'))} "
            f"(delta = {_f(t.get('delta'))}, n = {t.get('n')}); vacuous or failing "
            f"forms: {', '.join(t.get('vacuous_forms') or []) or 'none'}.",
            "",
            f"_{t.get('label', '')}_",
        ]
        held_out = [f for f in t.get("forms") or [] if f.get("name") == "held_out"]
        if t.get("vacuous") and held_out and not held_out[0].get("holds"):
            lines += [
                "",
                f"The held-out form fails: more demonstrations (n = {t.get('n')} training, "
                f"n_val = {t.get('n_val')} held-out now; raise [tasil] trajectories and "
                "heldout), or a closer fit (more [tasil] steps).",
            ]
    if d.get("l1drac"):
        lines += ["", "## L1-DRAC design", "", l1_design_text(d["l1drac"])]
    r = d["rho"]
    lines += [
        "",
        "## Total",
        "",
        f"rho_TaSIL = {_f(r['rho_tasil'])}, rho_L1 = {_f(r['rho_l1'])}, "
        f"rho = {_f(r['rho_total'])} ({r['source']})",
    ]
    if d["notes"]:
        lines += ["", "## Notes", ""] + [f"* {n}" for n in d["notes"]]
    return "\n".join(lines) + "\n"


def _matrix_lines(name: str, rows: list[list[float]]) -> list[str]:
    """``name = [[a, b], [c, d]]`` one row a line, 6 digits."""
    body = [f"  [{', '.join(_f(v) for v in row)}]" for row in rows]
    return [f"{name} =", *body]


def _coordinate_lines(co: dict[str, Any], verdict: str) -> list[str]:
    """The coordinates the certificate was computed in (Theta, P, the conversion factor to x)
    and, when it is not certified, every other coordinate candidate with its reasons, the one
    that came closest first (fewest failing checks, then the smallest radius in x)."""
    out: list[str] = []
    if co.get("system") == "z = Theta x":
        out += [
            "",
            "## Coordinates",
            "",
            "Computed in z = Theta x (docs/math/contraction.md section 5): rates, gains, "
            "constants, boxes and regions below are in z; the radii rho are mapped back to x "
            f"by factor_to_x = {_f(co.get('factor_to_x'))} >= ||Theta^-1||_2 (cond Theta >= "
            f"{_f(co.get('cond_theta_at_least'))}). Metric: {co.get('source', '')}.",
            "",
            "```",
            *_matrix_lines("Theta", co["theta"]),
            *_matrix_lines("P = Theta^T Theta", co["P"]),
            "```",
            "",
            "A region you give in [contraction] region is in x (it is mapped to z for you).",
        ]
    alts = co.get("alternatives") or []
    if verdict != "certified" and alts:
        ranked = sorted(alts, key=_closeness)
        out += ["", "## Other coordinates tried (closest first)", ""]
        for a in ranked:
            where = a["coordinates"] + (
                "" if a.get("cond_theta") is None else f" (cond Theta {_f(a['cond_theta'])})"
            )
            out.append(
                f"* {where}: {a['verdict'].replace('_', ' ')}, rho_TaSIL = "
                f"{_f(a.get('rho_tasil_x'))}, rho_L1 = {_f(a.get('rho_l1_x'))} (in x)"
            )
            out.extend(f"  * {r}" for r in a.get("verdict_reasons") or [])
    return out


_VERDICT_RANK = {"certified": 0, "conditional": 1, "not_certified": 2}


def _closeness(a: dict[str, Any]) -> tuple[int, int, float]:
    """Order of the coordinate candidates: verdict, failing checks, then the radius in x."""
    # JSON numbers: a float, None (not computed) or "inf" / "-inf" (provenance.json_float)
    parts = [float(v) for v in (a.get("rho_tasil_x"), a.get("rho_l1_x")) if v is not None]
    rho = sum(parts) if parts and all(math.isfinite(v) for v in parts) else math.inf
    return _VERDICT_RANK.get(a.get("verdict", ""), 3), int(a.get("failing", 0)), rho


def l1_constants_toml(cert: dict[str, Any], settings: Any, source: str = "") -> str:
    """A complete ``drip-cert design-l1`` input from a certificate's L1-DRAC part.

    ``[constants]``: every constant of ``l1drac.constants_used`` (with ``p_star``, ``m`` and
    ``lip_f``), each with its provenance in a comment; ``[design]``: ``p`` and the designed
    ``lambda_s``, and the spec's own design inputs (``[l1drac]`` ``omega``, ``Ts``, ``rho_r``,
    ``rho_a``, ``delta``, ``objective``, ``rho_budget``, ``front``) when it gives them, so that
    ``design-l1`` repeats the certificate's design search.

    Parameters
    ----------
    cert
        ``Certificate.to_dict()``.
    settings
        The spec's :class:`~drip_cert.spec.settings.L1Settings`.
    source
        The spec file, for the header comment.

    Raises
    ------
    SpecError
        The certificate has no L1-DRAC part, or a constant without a finite value (named, with
        the fix: give it in the spec's ``[constants]``).
    """
    from drip_cert.spec.settings import toml_text  # flint: keep off the report's import path

    l1 = cert.get("l1drac")
    if not l1:
        raise SpecError(
            "the certificate has no L1-DRAC part: add an [l1drac] table to the spec (p, "
            "lambda_s) to export its constants",
            field="l1drac",
            path=source or None,
        )
    used = l1["constants_used"]
    missing = [
        k
        for k, q in used.items()
        if isinstance(q, dict) and not (isinstance(q["value"], int | float))
    ]
    if missing:
        raise SpecError(
            f"constants without a finite value: {', '.join(missing)}; give them in the spec's "
            "[constants] table, then export again",
            field="l1drac.constants_used",
            path=source or None,
        )
    coords = cert.get("coordinates", {}).get("system", "x")
    lines = [
        f"# L1-DRAC constants of the certificate of {source or 'a spec'} "
        f"(drip-cert certify --export-l1-constants); verdict {cert['verdict']}.",
        f"# Coordinates: {coords}. Each value with how it was obtained (exact / sound / "
        "estimate / given).",
        "# Usage: drip-cert design-l1 THIS_FILE [--Ts ...] [--rho-budget ...]",
        *(
            []
            if coords == "x"
            else [
                "# The constants are those of the system in z = Theta x: design-l1's rho is in z;"
                f" rho in x <= factor_to_x * rho_z, factor_to_x = "
                f"{cert['coordinates'].get('factor_to_x')}"
            ]
        ),
        "",
        "[constants]",
    ]
    for name, q in used.items():
        if isinstance(q, dict):
            lines.append(f"{name} = {toml_text(float(q['value']))}  # {q['how']}: {q['source']}")
        else:
            lines.append(f"{name} = {toml_text(q)}")
    lines += ["", "[design]", f"p = {int(l1.get('p') or settings.p)}"]
    lambda_s = settings.lambda_s if settings.lambda_s is not None else l1.get("lambda_s")
    if lambda_s is None:
        raise SpecError(
            "the certificate has no designed lambda_s (the design is infeasible): give "
            "[l1drac] lambda_s in the spec to export a design-l1 file",
            field="l1drac.lambda_s",
            path=source or None,
        )
    lines.append(f"lambda_s = {toml_text(float(lambda_s))}")
    for key in ("omega", "Ts", "rho_r", "rho_a", "delta", "objective", "rho_budget"):
        value = getattr(settings, key)
        if value is not None:
            lines.append(f"{key} = {toml_text(value)}")
    if not settings.front:
        lines.append("front = false")
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
        "| eq | lhs | rhs | margin (float) | verified margin (Arb, lower end) | verified |",
        "|---|---|---|---|---|---|",
    ]
    for c in rep.get("conditions", []):
        lines.append(
            f"| ({c['eq']}) | {_f(c['lhs'])} | {_f(c['rhs'])} | {_f(c['margin'])} | "
            f"{_f(c.get('margin_lo'))} | {_f(c.get('verified', c['holds']))} |"
        )
    if rep.get("backoff"):
        lines += [
            "",
            "backed off from the boundary until every margin is verified in Arb: "
            + ", ".join(f"{k} x {v:.10g}" for k, v in rep["backoff"].items())
            + " (T_s is divided by its factor)",
        ]
    if rep.get("reason"):
        lines += ["", f"reason: {rep['reason']}"]
    lines += _l1_objective_lines(rep)
    lines += _l1_decomposition_lines(rep.get("decomposition"))
    return "\n".join(lines)


def _l1_decomposition_lines(dec: dict[str, Any] | None) -> list[str]:
    """rho_L1 term by term (``decomposition``, docs/math/l1drac.md section 5.5): each radius's
    terms with their share of ``(1 - k) rho^2``, largest first (terms of zero value left out)."""
    if not dec:
        return []
    b = dec["binding"]
    lines = [
        "",
        f"rho_L1 term by term at T_s = {_f(dec['Ts'])}: binding term {b['name']} (({b['radius']}), "
        f"{100 * b['share']:.1f} % of (1 - k_a) rho_a^2); sampled-data terms (24): "
        f"{100 * dec['sampling_share']:.1f} %; rho_L1(T_s -> 0) = {_f(dec['rho_Ts0'])} "
        f"(front), rho_L1(T_s) = {_f(dec['rho'])}",
        *_l1_mean_line(dec.get("rho_mean")),
        "",
        "| radius | term | eq | share of (1-k) rho^2 | T_s power | what |",
        "|---|---|---|---|---|---|",
    ]
    for key in ("rho_r", "rho_a"):
        for term in dec[key]["terms"]:
            if term["value"] == 0:
                continue
            lines.append(
                f"| {key} = {_f(dec[key]['value'])} | {term['name']} | ({term['condition']}) | "
                f"{100 * term['share']:.3g} % | {term['ts_power']} | {term['what']} |"
            )
    return lines


def _l1_mean_line(mean: dict[str, Any] | None) -> list[str]:
    """The bound of the mean gap max_t E||X_t - X*_t|| (docs/math/l1drac.md section 5.6)."""
    if not mean:
        return []
    by_p = ", ".join(_f(r) for r in mean["by_p"])
    line = (
        f"mean gap max_t E||X_t - X*_t|| < {_f(mean['value'])} (rho(p = {mean['p']}) at the same "
        f"omega, lambda_s, T_s; rho(1..p) = {by_p})"
    )
    if mean.get("kappa") is not None:
        k, kp = _f(mean["kappa"]), mean["kappa_p"]
        line += f"; best-order kappa({_f(mean['delta'])}) = {k} (p = {kp})"
    return [line]


def _l1_objective_lines(rep: dict[str, Any]) -> list[str]:
    """The objective, why this point, the knife-edge verdict and the (Ts, rho) Pareto front of
    an L1-DRAC design report (keys ``objective``, ``choice``, ``knife_edge``, ``front``)."""
    lines: list[str] = []
    if rep.get("objective"):
        lines += ["", f"objective: {rep['objective']}"]
        if rep.get("rho_budget") is not None:
            lines[-1] += f" (rho_budget = {_f(rep['rho_budget'])})"
    if rep.get("choice"):
        lines.append(f"chosen: {rep['choice']}")
    ke = rep.get("knife_edge") or {}
    if ke.get("is"):
        lines.append(f"KNIFE EDGE: {ke.get('reason', '')}")
    front = rep.get("front") or []
    if front:
        lines += [
            "",
            "(T_s, rho) Pareto front (every point a design verified in Arb; rho increases "
            "with T_s):",
            "",
            "| T_s [s] | rho | rho_r | rho_a | omega | lambda_s | verified | knife edge | source |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for pt in front:
            lines.append(
                f"| {_f(pt['Ts'], 3)} | {_f(pt['rho'])} | {_f(pt['rho_r'])} | "
                f"{_f(pt['rho_a'])} | {_f(pt['omega'])} | {_f(pt['lambda_s'])} | "
                f"{_f(pt['verified'])} | {'yes' if pt.get('knife_edge') else 'no'} | "
                f"{pt.get('source', '')} |"
            )
    return lines


def _validation_table(checks: list[dict[str, Any]]) -> list[str]:
    lines = [
        "| check | kind | bound | empirical | confidence bound | ratio bound/empirical "
        "| ratio bound/upper confidence | status |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in checks:
        status = c.get("status", "holds" if c.get("holds") else "violated")
        lines.append(
            f"| {c['name']} | {c.get('kind', '')} | {_f(c.get('bound'))} | "
            f"{_f(c.get('empirical'))} | {_f(c.get('confidence_low'))} | "
            f"{_f(c.get('ratio'))} | {_f(c.get('ratio_at_confidence'))} | "
            f"{status.upper() if status == 'violated' else status} |"
        )
    lines.append("")
    for c in checks:
        what = f"* {c['name']}: {c.get('what', '')}"
        if c.get("kind") == "radius" and c.get("exceed_count") is not None:
            what += (
                f"; {c['exceed_count']} of {c['n']} paths above rho (frequency "
                f"{_f(c['exceed_frequency'], 4)}, one-sided Clopper-Pearson lower bound "
                f"{_f(c['exceed_confidence_low'], 4)} vs delta {_f(c['delta'], 4)})"
            )
        elif c.get("kind") == "tail" and c.get("threshold") is not None:
            what += f"; threshold {_f(c['threshold'])}"
        if c.get("time") is not None:
            what += f"; worst recorded t = {_f(c['time'], 4)}"
        if c.get("reason"):
            what += f"; NOT CHECKED: {c['reason']}"
        lines.append(what)
    return lines


def validation_text(rep: dict[str, Any]) -> str:
    """Text rendering of a validation report: status first, then every check.

    Each check row shows the certified bound, the empirical statistic, the one-sided lower
    confidence bound that decides ``violated``, the ratio bound / empirical and the status; the
    lines below the table say what each check compares and why a check was not checked.
    """
    status = rep.get("status") or ("holds" if rep.get("holds") else "violated")
    label = {"holds": "HOLDS", "violated": "VIOLATED", "nothing_checked": "NOTHING CHECKED"}
    counts = rep.get("counts") or {}
    head = f"validation: {label.get(status, status.upper())}"
    if counts:
        head += (
            f" ({counts.get('holds', 0)} hold, {counts.get('violated', 0)} violated, "
            f"{counts.get('not_checked', 0)} not checked)"
        )
    if not rep.get("at_certified_parameters", True):
        head += " (L1 runs NOT at certified parameters)"
    lines = [head, ""]
    levels = {c.get("level") for c in rep.get("checks", []) if c.get("level") is not None}
    if levels:
        lines += [
            "confidence bound: one-sided lower bound of the empirical statistic at level "
            + ", ".join(_f(v, 4) for v in sorted(levels))
            + " (per-time checks: for all recorded times at once); a check is violated when it "
            "exceeds the bound",
            "",
        ]
    lines += _validation_table(rep.get("checks", []))
    short = rep.get("short_horizon_at_certified_parameters")
    if short:
        lines += ["", f"{short.get('note', 'short horizon')} ({short.get('paths')} paths):", ""]
        lines += _validation_table(short.get("checks", []))
    if rep.get("notes"):
        lines.append("")
    for note in rep.get("notes", []):
        lines.append(f"* {note}")
    return "\n".join(lines)


def reproduce_figure(
    res: Any, res_paper: Any, cert: Any, out: Any, at_certified: bool, name: str | None = None
) -> list[Any]:
    """The total imitation gap against time for the paper's three cases (PNG and SVG).

    Mean over paths with the t-interval band of the large ensemble, the paper-size ensemble as
    thin lines, and the certified bounds where they apply.
    """
    import matplotlib  # matplotlib: keep off the CLI start-up path

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # matplotlib: keep off the CLI start-up path

    out = Path(out)
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    cases = (
        ("policy", "(i) TaSIL, nominal system", "tab:green"),
        ("total_true", "(ii) TaSIL, uncertain system", "tab:red"),
        ("total_l1", "(iii) TaSIL + L1-DRAC, uncertain system", "tab:blue"),
    )
    for gap, label, color in cases:
        g = res.gap(gap)
        ax.plot(g.times, g.mean, color=color, lw=2, label=f"{label} ({g.n} paths)")
        ax.fill_between(g.times, g.ci_low, g.ci_high, color=color, alpha=0.25, lw=0)
        gp = res_paper.gap(gap)
        ax.plot(
            gp.times,
            gp.mean,
            color=color,
            lw=0.8,
            ls="--",
            label=f"{label.split(' ')[0]} {gp.n} paths (paper's ensemble)",
        )
    if cert.rho_tasil is not None and math.isfinite(cert.rho_tasil):
        ax.axhline(cert.rho_tasil, color="tab:green", ls=":", label="rho_TaSIL (certified)")
    if at_certified and cert.rho is not None and math.isfinite(cert.rho):
        ax.axhline(cert.rho, color="tab:blue", ls=":", label="rho = rho_TaSIL + rho_L1")
    elif at_certified and cert.rho_l1 is not None and math.isfinite(cert.rho_l1):
        ax.axhline(
            cert.rho_l1,
            color="tab:blue",
            ls=":",
            label="rho_L1 (certified bound on E||X_t - x'_t||; rho_TaSIL vacuous)",
        )
    title = "Total imitation gap E||X_t - x*_t|| (band: 95% t interval)"
    if name:
        failing = [c.id for c in cert.assumptions if not c.holds]
        verdict = cert.verdict.value.replace("_", " ") + (
            ": " + ", ".join(failing) + " fail" if failing else ""
        )
        title = f"{name} ({verdict})\n" + title
    if not at_certified:
        title += "\nL1-DRAC at practical parameters (certified T_s is not simulable)"
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("mean gap")
    ax.set_yscale("log")
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    paths = []
    for ext in ("png", "svg"):
        p = out / f"figure.{ext}"
        tmp = out / f".figure.tmp.{ext}"
        fig.savefig(tmp, dpi=130)
        tmp.replace(p)
        paths.append(p)
    plt.close(fig)
    return paths


def reproduce_markdown(summary: dict[str, Any], cert: Any, runs: dict[str, Any]) -> str:
    """``report.md`` of ``drip-cert reproduce paper-4d``."""
    lines = ['# DRIP paper, Section "Numerical Experiments", reproduced by drip-cert', ""]
    lines.append(
        f"**Certificate: {cert.verdict.value.replace('_', ' ').upper()}**; validation of the "
        + ", ".join(f"{k} ensemble: {v}" for k, v in summary["validation_status"].items())
        + ". The verdict's reasons are listed under Certificate below."
    )
    lines.append("")
    st = summary["settings"]
    lines.append(
        f"Settings: {'quick' if summary['quick'] else 'full'} run, horizon "
        f"{st['horizon']:g} s, dt = {st['dt']:g}, ensembles of {st['paths_paper']} "
        f"(the paper) and {st['paths_ours']} paths, {st['steps']} training steps."
    )
    lines += [
        "",
        "![total imitation gap](figure.png)",
        "",
        "## The paper's qualitative claims",
        "",
        "| case | claim | holds | detail |",
        "|---|---|---|---|",
    ]
    for c in summary["claims"]:
        lines.append(f"| {c['case']} | {c['claim']} | {_f(c['holds'])} | {c['detail']} |")
    hg = summary["heldout_gaps"]
    lines += [
        "",
        "## TaSIL vs behaviour cloning (same data and budget)",
        "",
        "| method | held-out gap mean | held-out gap max |",
        "|---|---|---|",
        f"| TaSIL (order 1) | {_f(hg['tasil']['mean'])} | {_f(hg['tasil']['max'])} |",
        f"| BC | {_f(hg['bc']['mean'])} | {_f(hg['bc']['max'])} |",
        "",
    ]
    lines += ["## Validation (bound vs empirical)", ""]
    for label, rep in runs.items():
        lines.append(f"### {label} ensemble")
        lines.append("")
        lines.append(validation_text({k: v for k, v in rep.items() if k != "_result"}))
        lines.append("")
    lines += ["## Certificate", "", certificate_markdown(cert)]
    t = summary["timings"]
    lines += ["## Timings", "", "| step | seconds |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in t.items()]
    return "\n".join(lines) + "\n"


def comparison_text(rows: dict[str, dict[str, Any]]) -> str:
    """``train --compare``: one line per method, the held-out gap beside the certificate's
    verdict (whole certificate and TaSIL part) and its ``rho_TaSIL`` and ``rho``."""

    def num(v: Any) -> str:
        return "-" if v is None else f"{v:.4g}"

    head = (
        f"  {'method':<7} {'gap mean':>10} {'gap max':>10} {'labels':>7} {'verdict':<14} "
        f"{'TaSIL part':<14} {'rho_TaSIL':>10} {'rho':>10}"
    )
    lines = ["methods on the same demonstrations and label budget:", head]
    for m, g in rows.items():
        lines.append(
            f"  {m:<7} {num(g.get('heldout_gap_mean')):>10} {num(g.get('heldout_gap_max')):>10} "
            f"{g.get('labels', 0):>7} {str(g.get('verdict', '-')):<14} "
            f"{str(g.get('tasil_verdict', '-')):<14} {num(g.get('rho_tasil')):>10} "
            f"{num(g.get('rho')):>10}"
        )
    return "\n".join(lines)


def train_text(summary: dict[str, Any], out: str) -> str:
    """The text ``drip-cert train`` prints: the policy, its held-out gap beside the other
    method's, and the certificate's verdict with its binding condition and margin."""
    lines = [
        f"trained {summary['method']} ({summary['architecture']} policy) in "
        f"{summary['wall_s']:.1f} s, stop: {summary['stop_reason']} (best step "
        f"{summary['best_step']}); written to {out}",
        f"held-out gap mean {summary['heldout_gap_mean']:.4g}, max "
        f"{summary['heldout_gap_max']:.4g} (threshold {summary['heldout_gap_threshold']:.4g})",
    ]
    rows = summary["comparison"]
    if any("verdict" in g for g in rows.values()):
        lines.append(comparison_text(rows))
    else:
        for m, g in rows.items():
            if m != summary["method"]:
                lines.append(
                    f"  {m} on the same data and budget: held-out gap mean "
                    f"{g['heldout_gap_mean']:.4g}, max {g['heldout_gap_max']:.4g}"
                )
    b = summary.get("certificate")
    if b is not None:
        lines.append(f"certificate: {b['verdict'].upper()}; binding condition: {b['text']}")
    if len(summary.get("rounds", ())) > 1:
        lines.append(
            "rounds (--until-certified): "
            + ", ".join(
                f"{r['steps']} steps -> {r['binding']['verdict'] if r['binding'] else 'n/a'}"
                for r in summary["rounds"]
            )
        )
    return "\n".join(lines)


# ------------------------------------------------------------------ validation report + figure
#: the gaps drawn in the validation figure: (gap, label, certified bound key of ``rho``, what the
#: bound is about); a gap the run does not have (recorded data without those processes) is left out
_VALIDATION_PANELS: tuple[tuple[str, str, str, str], ...] = (
    (
        "policy",
        "policy gap E||x'_t - x*_t|| (learned vs expert, nominal)",
        "rho_tasil",
        "rho_TaSIL: (1 - delta) radius of max_t ||x'_t - x*_t|| (checked as policy_radius)",
    ),
    (
        "uncertainty_l1",
        "uncertainty gap E||X_t - x'_t|| (learned + L1-DRAC on the true system vs nominal)",
        "rho_l1",
        "rho_L1: certified bound on ||X_t - x'_t||_{L_2p} >= E||X_t - x'_t||",
    ),
    (
        "total_l1",
        "total gap E||X_t - x*_t|| (learned + L1-DRAC on the true system vs expert)",
        "rho_total",
        "rho = rho_TaSIL + rho_L1 (the paper's total; information, see total_tail)",
    ),
)

LOG_SCALE_RATIO = 20.0
"""A panel whose certified bound is more than this many times the largest gap (upper confidence
end) is drawn on a log axis, so that both are readable."""

VALIDATION_FILES = ("validation.json", "validation.md", "validation.png")
"""What ``drip-cert validate --out DIR`` writes into ``DIR`` (with ``simulation/`` for a
simulated run)."""


def _parameters_label(rep: dict[str, Any]) -> str:
    """The at / NOT at certified parameters sentence of a validation report."""
    p = rep.get("l1_parameters") or {}
    values = ", ".join(
        f"{k} = {_f(p[k], 4)}" for k in ("omega", "lambda_s", "Ts") if p.get(k) is not None
    )
    if rep.get("at_certified_parameters"):
        return "L1-DRAC at the certified parameters" + (f" ({values})" if values else "")
    return (
        "L1-DRAC NOT at the certified parameters"
        + (f" (run at {values})" if values else "")
        + ": its results do not validate the certificate's L1-DRAC part"
    )


def _source_label(rep: dict[str, Any]) -> str:
    sim = rep.get("simulation") or {}
    if sim.get("source") == "recorded data":
        return f"recorded data {sim.get('file', '')} ({sim.get('n_paths', '?')} paths)".replace(
            "  ", " "
        )
    n = sim.get("n_paths_done")
    return "Monte-Carlo simulation" + (f" ({n} paths)" if n is not None else "")


def validation_markdown(rep: dict[str, Any], figure: str | None = "validation.png") -> str:
    """Markdown rendering of a validation report (:meth:`ValidationReport.to_dict`).

    Status and the at / NOT at certified parameters line first, then the certificate's verdict
    and bounds, the figure (``figure``: a path relative to the Markdown file, ``None`` for none),
    every check (bound, empirical, one-sided confidence bound, ratio, status), the largest
    empirical gaps with their confidence intervals, and the notes.
    """
    cert = rep.get("certificate") or {}
    name = (cert.get("system") or {}).get("name", "")
    status = rep.get("status", "nothing_checked")
    label = {"holds": "HOLDS", "violated": "VIOLATED", "nothing_checked": "NOTHING CHECKED"}
    counts = rep.get("counts") or {}
    rho = cert.get("rho") or {}
    lines = [
        f"# drip-cert validation: {name}",
        "",
        f"**{label.get(status, status.upper())}** ({counts.get('holds', 0)} hold, "
        f"{counts.get('violated', 0)} violated, {counts.get('not_checked', 0)} not checked) "
        f"against {_source_label(rep)} on [0, {_f(rep.get('horizon'), 4)}] s.",
        "",
        f"**{_parameters_label(rep)}.**",
        "",
        f"Certificate: {str(cert.get('verdict', 'n/a')).upper()}; rho_TaSIL = "
        f"{_f(rho.get('rho_tasil'))}, rho_L1 = {_f(rho.get('rho_l1'))}, rho = "
        f"{_f(rho.get('rho_total'))} (certified horizon T = "
        f"{_f(rep.get('certified_horizon'), 4)} s).",
    ]
    if status == "violated":
        bad = [c["name"] for c in rep.get("checks", []) if c.get("status") == "violated"]
        lines += ["", f"Violated: {', '.join(bad) or 'see the short-horizon run'}."]
    if figure:
        lines += ["", f"![empirical gaps against the certified bounds]({figure})"]
    lines += ["", "## Checks", ""]
    lines += _validation_table(rep.get("checks", []))
    short = rep.get("short_horizon_at_certified_parameters")
    if short:
        lines += ["", f"### {short.get('note', 'short horizon')} ({short.get('paths')} paths)", ""]
        lines += _validation_table(short.get("checks", []))
    emp = rep.get("empirical") or {}
    rows = [(k, v) for k, v in emp.items() if isinstance(v, dict) and "value" in v]
    if rows:
        lines += [
            "",
            "## Largest mean gaps",
            "",
            "| gap | max_t mean | confidence interval | at t |",
            "|---|---|---|---|",
        ]
        lines += [
            f"| {k} | {_f(v.get('value'))} | [{_f(v.get('ci_low'))}, {_f(v.get('ci_high'))}] | "
            f"{_f(v.get('argmax_time'), 4)} |"
            for k, v in rows
        ]
    if rep.get("notes"):
        lines += ["", "## Notes", ""] + [f"* {n}" for n in rep["notes"]]
    return "\n".join(lines) + "\n"


def _bound(rho: dict[str, Any], key: str) -> float | None:
    v = rho.get(key)
    if v is None or isinstance(v, str):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def validation_figure(report: Any, path: Any) -> Path:
    """The validation figure (PNG): each empirical mean gap over time with its confidence band
    and the certified bound drawn in, titled with the status and whether the L1-DRAC runs are at
    the certified parameters.

    ``report`` is a :class:`~drip_cert.validate.run.ValidationReport` (simulated or recorded
    data: its ``result.gap(name)`` gives the per-time statistics). Written atomically to ``path``.
    """
    import matplotlib  # matplotlib: keep off the CLI start-up path

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # matplotlib: keep off the CLI start-up path

    rep = report.to_dict()
    rho = (rep.get("certificate") or {}).get("rho") or {}
    at_cert = bool(rep.get("at_certified_parameters"))
    panels = []
    for gap, label, key, bound_label in _VALIDATION_PANELS:
        try:
            g = report.result.gap(gap)
        except (KeyError, AttributeError):
            continue
        if g.n > 0 and len(g.times) > 0:
            panels.append((g, label, key, bound_label))
    path = Path(path)
    fig, axes = plt.subplots(
        max(len(panels), 1), 1, figsize=(7.5, 2.6 * max(len(panels), 1) + 0.8), squeeze=False
    )
    for ax, (g, label, key, bound_label) in zip(axes[:, 0], panels, strict=False):
        ax.plot(g.times, g.mean, color="tab:blue", lw=1.8, label=f"empirical mean ({g.n} paths)")
        ax.fill_between(
            g.times,
            g.ci_low,
            g.ci_high,
            color="tab:blue",
            alpha=0.25,
            lw=0,
            label=f"{100 * g.level:g}% confidence band",
        )
        b = _bound(rho, key)
        l1_part = key != "rho_tasil"
        if b is not None and (at_cert or not l1_part):
            ax.axhline(b, color="tab:red", ls="--", lw=1.5, label=bound_label)
        elif b is not None:
            ax.axhline(
                b,
                color="tab:gray",
                ls=":",
                lw=1.2,
                label=bound_label.split(":")[0] + " (NOT comparable: not at certified parameters)",
            )
        ax.set_title(label, fontsize=9)
        ax.set_ylabel("gap")
        top = float(np.nanmax(g.ci_high)) if np.any(np.isfinite(g.ci_high)) else 0.0
        if b is not None and top > 0 and b / top > LOG_SCALE_RATIO:
            # a bound far above the gap: a log axis shows both (the gap is 0 at t = 0: masked)
            ax.set_yscale("log", nonpositive="mask")
            ax.set_ylabel("gap (log scale)")
        else:
            ax.set_ylim(bottom=0.0)
        ax.legend(fontsize=7, loc="best")
    if not panels:
        axes[0, 0].text(0.5, 0.5, "no gap series in this run", ha="center", va="center")
    axes[-1, 0].set_xlabel("t [s]")
    name = ((rep.get("certificate") or {}).get("system") or {}).get("name", "")
    status = str(rep.get("status", "")).replace("_", " ").upper()
    fig.suptitle(
        f"{name}: validation {status}\n"
        + ("AT certified parameters" if at_cert else "NOT at certified parameters (L1-DRAC)"),
        fontsize=10,
        color="black" if at_cert else "tab:red",
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.png")
    try:
        fig.savefig(tmp, dpi=120)
        tmp.replace(path)
    finally:
        plt.close(fig)
        if tmp.exists():
            tmp.unlink()
    return path


def write_validation_outputs(report: Any, out: Any) -> list[Path]:
    """Write ``validation.md`` and ``validation.png`` of ``report`` into ``out`` (atomically);
    ``validation.json`` is the caller's. Returns the two paths."""
    out = Path(out)
    fig = validation_figure(report, out / "validation.png")
    md = out / "validation.md"
    atomic_write_text(md, validation_markdown(report.to_dict(), figure=fig.name))
    return [md, fig]

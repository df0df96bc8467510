"""Human-readable reports: Markdown for certificates and validations, text for the L1 designer."""

from __future__ import annotations

import math
from pathlib import Path
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
    verdict = {
        "certified": "CERTIFIED",
        "conditional": "CONDITIONAL",
        "not_certified": "NOT CERTIFIED",
    }[d["verdict"]]
    lines.append(f"**{verdict}** (n = {s['n']}, m = {s['m']}, d = {s['d']}, T = {s['horizon']:g})")
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
    if d.get("parts"):
        lines.append("")
        lines.append("Parts: " + "; ".join(f"{k}: {v['verdict']}" for k, v in d["parts"].items()))
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
    return "\n".join(lines)


def _validation_table(checks: list[dict[str, Any]]) -> list[str]:
    lines = [
        "| check | kind | bound | empirical | confidence bound | ratio bound/empirical | status |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in checks:
        status = c.get("status", "holds" if c.get("holds") else "violated")
        lines.append(
            f"| {c['name']} | {c.get('kind', '')} | {_f(c.get('bound'))} | "
            f"{_f(c.get('empirical'))} | {_f(c.get('confidence_low'))} | "
            f"{_f(c.get('ratio'))} | {status.upper() if status == 'violated' else status} |"
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
    for m, g in summary["comparison"].items():
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

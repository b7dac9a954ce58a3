"""A static HTML page for a run: sections of text, tables and figures.

No network, no scripts: the page only links files that sit beside it, so the
folder can be zipped and opened anywhere. Sections are built from what the
stages return (the posterior report's content, a criticism's record), not from
files read back.
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from identification.artifacts import atomic_write_text
from identification.criticism.words import SMALL

__all__ = [
    "Section",
    "criticism_section",
    "missing_links",
    "posterior_sections",
    "rounds_text",
    "surrogate_section",
    "write_index",
]

_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em;
       color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #446; } h2 { margin-top: 2em; color: #335; }
figure { display: inline-block; margin: 0.5em; vertical-align: top; max-width: 100%; }
figure img { max-width: 520px; width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; max-width: 520px; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
td, th { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: right; }
th { background: #eef; } td:first-child, th:first-child { text-align: left; }
pre { background: #f6f6f6; padding: 0.6em; overflow-x: auto; }
nav a { margin-right: 1em; }
"""


@dataclass
class Section:
    """One section of the page.

    ``figures`` are (path relative to the page, caption) pairs; ``tables``
    are (title, rows) with rows a list of dicts sharing keys; ``files`` are
    (path, label) links to data files.
    """

    title: str
    text: str = ""
    figures: Sequence[tuple[str, str]] = field(default_factory=list)
    tables: Sequence[tuple[str, Sequence[Mapping]]] = field(default_factory=list)
    files: Sequence[tuple[str, str]] = field(default_factory=list)
    code: str = ""

    @property
    def anchor(self) -> str:
        return "".join(c if c.isalnum() else "-" for c in self.title.lower()).strip("-")


def _format(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, dict)):
        return html.escape(json.dumps(value, default=str))
    return html.escape(str(value))


def _table(title: str, rows: Sequence[Mapping]) -> str:
    if not rows:
        return f"<p><em>{html.escape(title)}: none</em></p>"
    keys = list(rows[0])
    head = "".join(f"<th>{html.escape(str(k))}</th>" for k in keys)
    body = "".join(
        "<tr>" + "".join(f"<td>{_format(row.get(k, ''))}</td>" for k in keys) + "</tr>"
        for row in rows
    )
    return f"<h3>{html.escape(title)}</h3><table><tr>{head}</tr>{body}</table>"


def _section(section: Section) -> str:
    parts = [f'<h2 id="{section.anchor}">{html.escape(section.title)}</h2>']
    if section.text:
        parts += [f"<p>{html.escape(p)}</p>" for p in section.text.split("\n\n")]
    if section.code:
        parts.append(f"<pre>{html.escape(section.code)}</pre>")
    for title, rows in section.tables:
        parts.append(_table(title, rows))
    for src, caption in section.figures:
        src_attr = html.escape(Path(src).as_posix(), quote=True)
        parts.append(
            f'<figure><a href="{src_attr}"><img src="{src_attr}" alt="{html.escape(caption)}">'
            f"</a><figcaption>{html.escape(caption)}</figcaption></figure>"
        )
    if section.files:
        links = ", ".join(
            f'<a href="{html.escape(Path(p).as_posix(), quote=True)}">{html.escape(label)}</a>'
            for p, label in section.files
        )
        parts.append(f"<p>Data: {links}</p>")
    return "\n".join(parts)


#: Columns of the posterior summary shown on the page.
_SUMMARY_COLUMNS = ("variable", "index", "mean", "sd", "eti94_lb", "eti94_ub", "ess_bulk", "r_hat")


def posterior_sections(
    content: Mapping[str, Any], folder: str | os.PathLike, page_folder: str | os.PathLike
) -> list[Section]:
    """Sections of a posterior report: ``content`` is what :func:`pm_joint.report_folder.report`
    returned for its folder ``folder``."""
    rel = Path(os.path.relpath(folder, page_folder))
    files = [f for f in content["files"] if f.endswith(".png")]
    summary_rows = [
        {k: v for k, v in row.items() if k in _SUMMARY_COLUMNS} for row in content["summary"]
    ]
    pdf_rows = [
        {
            "level": level,
            "amplitude_mm": entry.get("amplitude_mm"),
            "measured_family": entry["measured_fit"]["family"],
            "sampled_family": entry["sampled_fit"]["family"],
            "ks_statistic": entry["distances"]["ks_statistic"],
            "ks_pvalue": entry["distances"]["ks_pvalue"],
            "wasserstein_hz": entry["distances"]["wasserstein"],
        }
        for level, entry in content["level_pdfs"].items()
    ]
    sampler = content.get("sampler", {})
    verdict = content.get("convergence") or {}
    convergence_rows = [
        {k: row[k] for k in ("variable", "r_hat", "ess_bulk", "ess_tail", "ok")}
        for row in verdict.get("parameters", [])
    ]
    population = content.get("population_model") or {}
    check = content.get("identifiability") or {}
    loo = content.get("loo")
    paragraphs = [
        # The verdict first: an unconverged run must not read as a result.
        f"Convergence verdict: {verdict.get('headline', 'not computed (an older report)')}",
        *(f"Not computed from this posterior: {line}." for line in content.get("not_computed", [])),
        population.get("meaning", ""),
        f"Identifiability: {check['text']}." if check else "",
        _loo_text(loo),
        f"Sampler: {sampler.get('sampler')}"
        + (f" ({sampler['reason']})" if sampler.get("reason") else "")
        + f", {sampler.get('draws')} draws × {sampler.get('chains')} chains; "
        f"mean acceptance {_number(sampler.get('acceptance_rate'), '.2f')}.",
    ]
    sections = [
        Section(
            "Stochastic updating" + ("" if verdict.get("converged", False) else " — NOT CONVERGED"),
            "\n\n".join(p for p in paragraphs if p),
            tables=[
                ("convergence per variable", convergence_rows),
                ("posterior summary", summary_rows),
            ],
            figures=[(str(rel / f), f.removesuffix(".png").replace("_", " ")) for f in files],
            files=[(str(rel / "report.json"), "report.json")],
        ),
    ]
    if not pdf_rows:
        return sections
    return [
        *sections,
        Section(
            "PDFs at low, mid and high amplitude",
            "Measured against sampled frequencies, each with its best-fitting distribution "
            "family (AIC) and the distances between them (the paper's Fig. 22).",
            tables=[("per amplitude level", pdf_rows)],
        ),
    ]


def _number(value: Any, spec: str) -> str:
    """A number in words at ``spec``; what is not a number (None: not recorded) as it is."""
    return format(value, spec) if isinstance(value, int | float) else str(value)


def _loo_text(loo: Any) -> str:
    """LOO in words: a refusal, the figures, or nothing."""
    if loo is None:
        return ""
    if isinstance(loo, str):
        return f"LOO: {loo}."
    return (
        f"LOO over {loo['n_points']} measured points: elpd {loo['elpd_loo']:.1f} "
        f"(SE {loo['se']:.1f}), p_loo {loo['p_loo']:.1f}; {loo['pareto_k_above_0.7']} points "
        "with Pareto k > 0.7 (their LOO estimates are unreliable)."
    )


def rounds_text(rounds: Sequence[Mapping[str, Any]]) -> str:
    """Every round's summary in order, each headed by its action and verdict when there
    are several (what ``pm-joint criticize`` prints)."""
    parts = []
    for k, report in enumerate(rounds, start=1):
        head = f"--- round {k} of {len(rounds)} ({report['action']}): {report['verdict']}\n"
        parts.append((head if len(rounds) > 1 else "") + report["summary"])
    return "\n".join(parts)


def _round_finding(k: int, n: int, report: Mapping[str, Any]) -> str:
    """One round's finding: its verdict, where its model failed and what it proposed."""
    text = f"Round {k} of {n} ({report['action']}): {report['verdict_text']}."
    # A round's record says where its model failed only in its summary's "fails:" lines.
    fails = [line.removeprefix("fails: ") for line in report["summary"].splitlines()
             if line.startswith("fails: ")]  # fmt: skip
    if fails:
        text += f" Where it fails: {'; '.join(fails)}."
    proposed = [entry for entry in report.get("ranking", []) if entry.get("reading")]
    if report.get("significant") and proposed:
        best = proposed[0]
        text += f" Most likely missing: {best['effect']}, {best['reading']}."
    return text


def criticism_section(
    content: Mapping[str, Any], folder: str | os.PathLike, page_folder: str | os.PathLike
) -> Section:
    """Section of a criticism: ``content`` is its record (``Criticism.to_dict()``, or the
    ``criticism.json`` of an earlier run) and ``folder`` where its figures were written.

    The section leads with each round's finding (what was missing, where the model of
    that round failed), in order; the final model's state comes after them.
    """
    rel = Path(os.path.relpath(folder, page_folder))
    rounds = content.get("rounds") or [content]  # a record written before rounds existed
    verdict = (
        "Something significant is missing." if content["significant"]
        else "Nothing significant missing."
    )  # fmt: skip
    if content.get("small"):  # a record written before the qualifier has none
        verdict += f" It is {SMALL.removeprefix('missing, ')}."
    nowhere = "at no single level beyond the scatter" if content.get("small") else "nowhere"
    fails = "; ".join(r.get("text", str(r)) for r in content.get("fails_at", [])) or nowhere
    findings = [_round_finding(k, len(rounds), r) for k, r in enumerate(rounds, start=1)]
    final = f"The final model, {content['equation']}: {verdict} Where it fails: {fails}."
    rankings = [
        (f"round {k} ({r['action']}): ranked missing effects", r.get("ranking", []))
        for k, r in enumerate(rounds, start=1)
    ]
    return Section(
        "Model criticism",
        "\n\n".join([*findings, final]),
        code=rounds_text(rounds),
        tables=[
            *rankings,
            (
                "error history",
                [
                    {k: v for k, v in step.items() if not isinstance(v, (list, dict))}
                    for step in content.get("history", [])
                ],
            ),
        ],
        figures=[
            (str(rel / "comparison.png"), "measured vs predicted, residual bands"),
            (str(rel / "signatures.png"), "residual beside the top candidates' signatures"),
            (str(rel / "history.png"), "the error along the loop"),
        ],
        files=[(str(rel / "criticism.json"), "criticism.json")],
    )


#: The value channels of an amplitude-grid surrogate's test figures, as the report names them.
_GRID_VALUE_CHANNELS = ("frequency_hz", "damping_ratio", "base_acceleration_m_s2")


def _ratio_text(value: float | None, limit: float) -> str:
    if value is None:
        return "unknown (no figure)"
    return f"{value:.3g} (target ≤ {limit:g}: {'met' if value <= limit else 'NOT MET'})"


def surrogate_section(
    metadata: Mapping[str, Any], folder: str | os.PathLike, page_folder: str | os.PathLike
) -> Section:
    """Section of a trained surrogate from its sidecar (``surrogate.json``) in ``folder``.

    Says how many curves were requested, generated and used for train /
    validation / test by origin, which measured curves were left out or
    down-weighted and why, whether the likelihood's curves were training data,
    and the independent test figures beside the baselines and the assembly
    scatter, with the acceptance of issue #15 (frequency ≤ 0.1 × scatter at every
    amplitude, ≤ 0.1 × the linear baseline).
    """
    rel = Path(os.path.relpath(folder, page_folder))
    training, test = metadata["training"], metadata.get("test") or {}
    data, network = training.get("data", {}), training.get("network", {})
    counts = data.get("counts", {})
    splits = data.get("splits", {})
    measured_curves = data.get("measured_curves", {})
    excluded = data.get("measured_excluded", {})
    amplitudes = metadata.get("amplitudes_m") or []
    used = splits.get("all", {})
    n_used = sum(used.values())
    n_named = counts.get("requested", 0) + len(measured_curves) + len(excluded)
    head = training["config"].get("head_degree", 0)
    text = [
        f"Amplitude-grid surrogate: frequency, damping ratio, base acceleration and the "
        f"has_backbone mask on {len(amplitudes)} response amplitudes"
        + (f" over {1e3 * amplitudes[0]:.3g}–{1e3 * amplitudes[-1]:.3g} mm" if amplitudes else "")
        + f"; the paper's network ({network.get('parameters', {}).get('exported', '?')} "
        "weights)"
        + (f" on the residual of a degree-{head} regression head" if head else "")
        + (
            ", the damping learnt as the decay rate 2π f ζ"
            if training["config"].get("damping_target") == "decay_rate"
            else ""
        )
        + ", exported to ONNX and run by onnxruntime.",
        f"Curves: {counts.get('requested', 0)} analytical requested, "
        f"{counts.get('generated', 0)} generated, every one kept "
        f"({counts.get('curves_with_mask', 0)} with a has_backbone mask somewhere); "
        f"{len(measured_curves) + len(excluded)} measured offered, {len(measured_curves)} "
        f"added. Used {n_used} of the {n_named} curves named "
        f"({100 * n_used / max(n_named, 1):.1f} %).",
    ]
    grid = data.get("grid")
    if grid:
        covering = grid["curves_covering"]
        low, high = grid["measured_range_m"]
        text.append(
            f"The grid spans the amplitudes at least {grid['min_curves']} of the "
            f"{grid['n_curves']} measured curves cover (they span {1e3 * low:.3g}–"
            f"{1e3 * high:.3g} mm together), so the assembly scatter is defined at every grid "
            f"amplitude; curves covering each, from the smallest amplitude up: "
            f"{', '.join(map(str, covering))}."
        )
    if excluded:
        text.append(
            f"Left out: {len(excluded)} measured curves: "
            + "; ".join(f"{k}: {v}" for k, v in excluded.items())
            + "."
        )
    # A weight acts in training only: a held-out (test) curve is scored whatever its weight.
    lowered = {k: v for k, v in measured_curves.items() if v["weight"] < 1 and v["split"] != "test"}
    if lowered:
        text.append(
            "Down-weighted (label misfit beyond the threshold, weight (threshold/misfit)²): "
            + ", ".join(f"{k} ({v['weight']:.2g})" for k, v in lowered.items())
            + "."
        )
    in_training = data.get("measured_in_training", [])
    text.append(
        f"{len(in_training)} of the likelihood's measured curves were also training or "
        "validation data of this surrogate"
        + (
            " (hold them out with hold_out_measured=True)."
            if in_training
            else ": they were held out, in the test split."
        )
    )
    tables = [
        (
            "curves used, by origin and split",
            [{"origin": origin, **row} for origin, row in splits.items()],
        )
    ]
    for origin in ("analytical", "measured"):
        part = test.get(origin)
        if not part:
            text.append(f"Test split, {origin} curves: none.")
            continue
        rows = []
        for channel in _GRID_VALUE_CHANNELS:
            models, ratios = part["models"], part["ratios"].get(channel, {})
            if channel not in models["surrogate"]:
                continue
            rows.append(
                {
                    "channel": channel,
                    **{f"RMSE {m}": models[m][channel]["rmse"] for m in models},
                    "÷ linear": ratios.get("to_linear"),
                    "÷ scatter (worst amplitude)": ratios.get("to_scatter_max"),
                    "linear ÷ scatter": ratios.get("linear_to_scatter_max"),
                }
            )
        tables.append((f"independent test split, {part['n_curves']} {origin} curves", rows))
    analytical = (test.get("analytical") or {}).get("ratios", {}).get("frequency_hz", {})
    limits = test.get("targets", {})
    if analytical:
        text.append(
            "Acceptance (analytical test curves, frequency): error ÷ assembly scatter at the "
            f"worst of the {analytical.get('levels_with_scatter')} of {len(amplitudes)} "
            "amplitudes where at least 3 measured curves give a scatter "
            + _ratio_text(analytical.get("to_scatter_max"), limits.get("to_scatter_max", 0.1))
            + "; ÷ the linear baseline's "
            + _ratio_text(analytical.get("to_linear"), limits.get("to_linear", 0.1))
            + "."
        )
    by_channel = data.get("label_misfit_by_channel", {})
    rows = [
        {"curve": k, "split": v["split"], "weight": v["weight"]} for k, v in measured_curves.items()
    ] + [{"curve": k, "split": "left out", "weight": 0.0} for k in excluded]
    for row in rows:
        misfits = by_channel.get(row["curve"]) or {}
        row.update({f"misfit {c}": misfits.get(c) for c in _GRID_VALUE_CHANNELS})
    if rows:
        text.append(
            "Label misfit: the RMS over a measured curve's amplitudes of (its label's "
            "backbone − the curve) in assembly standard deviations, per channel; a curve's "
            "weight follows its frequency misfit."
        )
    tables.append(("measured curves: split, loss weight, label misfit", rows))
    return Section(
        "Neural surrogate",
        "\n\n".join(text),
        tables=tables,
        figures=[(str(rel / "surrogate_predictions.png"), "test curves vs surrogate")],
        files=[
            (str(rel / "surrogate.onnx"), "surrogate.onnx"),
            (str(rel / "surrogate.json"), "surrogate.json"),
            (str(rel / "dataset.npz"), "dataset.npz"),
        ],
    )


def write_index(folder: str | os.PathLike, title: str, sections: Sequence[Section]) -> Path:
    """Write ``folder/index.html``; every link is relative to ``folder``."""
    folder = Path(folder)
    nav = " ".join(f'<a href="#{s.anchor}">{html.escape(s.title)}</a>' for s in sections)
    page = (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>"
        f"<h1>{html.escape(title)}</h1><nav>{nav}</nav>\n"
        + "\n".join(_section(s) for s in sections)
        + "\n</body></html>\n"
    )
    return atomic_write_text(folder / "index.html", page)


def missing_links(index: str | os.PathLike) -> list[str]:
    """``src``/``href`` targets of a page that do not exist beside it (anchors excluded)."""
    from html.parser import HTMLParser

    index = Path(index)
    targets: list[str] = []

    class _Links(HTMLParser):
        def handle_starttag(self, tag, attrs):
            for name, value in attrs:
                if name in ("src", "href") and value and not value.startswith("#"):
                    targets.append(value)

    _Links().feed(index.read_text(encoding="utf-8"))
    return [t for t in targets if not (index.parent / t).exists()]

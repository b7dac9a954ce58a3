"""The end-to-end demo on the embedded default: a virtual TRC campaign.

Runs every stage of :mod:`pm_joint.pipeline` in order and leaves a browsable
report (``index.html``) in the output folder.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from identification.artifacts import atomic_write_text
from identification.model import JointModel
from pm_joint import pipeline
from pm_joint.html import Section, write_index


@dataclass(frozen=True)
class DemoSize:
    """How big the demo runs: the paper's size, or a quick check for CI."""

    assemblies: int
    levels: int
    sindy_records: int
    draws: int
    tune: int
    chains: int


SIZES = {
    "full": DemoSize(assemblies=25, levels=10, sindy_records=3, draws=30_000, tune=2_000, chains=2),
    "small": DemoSize(assemblies=4, levels=6, sindy_records=2, draws=600, tune=200, chains=1),
}

#: The SINDy library of the demo: the paper's polynomial and friction terms.
DEMO_LIBRARY = (
    "linear_stiffness",
    "viscous_damping",
    "quadratic_stiffness",
    "cubic_stiffness",
    "abs_stiffness",
    "quadratic_damping",
    "cubic_damping",
    "coulomb_friction",
)


class _Stages:
    """Runs stages with a timing line each, collecting the report sections."""

    def __init__(self) -> None:
        self.sections: list[Section] = []
        self.timings: dict[str, float] = {}

    def run(self, name: str, function, *args, **kwargs):
        print(f"[pm-joint demo] {name} ...", flush=True)
        start = time.perf_counter()
        result = function(*args, **kwargs)
        self.timings[name] = round(time.perf_counter() - start, 2)
        print(f"[pm-joint demo] {name}: {self.timings[name]:.1f} s", flush=True)
        return result


def run_demo(out: str | Path = "demo_out", size: str = "full") -> Path:
    """Run the whole chain; returns the path of ``index.html``."""
    if size not in SIZES:
        raise ValueError(f"size must be one of {sorted(SIZES)}, got {size!r}")
    cfg = SIZES[size]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stages = _Stages()
    records = out / "records"

    stages.run(
        "virtual campaign", pipeline.write_rig_campaign, "trc-like", records,
        assemblies=cfg.assemblies, levels=cfg.levels, seed=0,
    )  # fmt: skip
    measured = stages.run("backbones", pipeline.campaign_backbones, records, out / "backbones.csv")
    stages.sections.append(
        Section(
            "Measured backbones",
            f"{len(measured)} backbones extracted from the records of the virtual TRC "
            "campaign (trc-like rig preset: softening by microslip, then hardening).",
            figures=[("backbones.png", "frequency and damping against amplitude")],
            files=[("backbones.csv", "backbones.csv")],
        )
    )

    identification = stages.run(
        "SINDy identification", pipeline.identify_campaign, records, DEMO_LIBRARY,
        records=cfg.sindy_records, out=out / "model.json",
    )  # fmt: skip
    model: JointModel = identification.model
    stages.sections.append(
        Section(
            "SINDy identification",
            f"Library: {', '.join(DEMO_LIBRARY)}.",
            code=f"{model.equation()}\n\n{identification.summary()}",
            figures=[
                ("model_validation_velocity.png", "measured vs simulated velocity (Fig. 9)"),
                (
                    "model_validation_acceleration.png",
                    "measured vs simulated acceleration (Fig. 10)",
                ),
            ],
            files=[("model.json", "model.json")],
        )
    )

    stages.run(
        "analytical backbones", pipeline.analytical_backbones, model, measured,
        out / "analytical.png",
    )  # fmt: skip
    stages.sections.append(
        Section(
            "Analytical backbones",
            "The identified model under PLL control (time simulation) and by multi-harmonic "
            "balance, over the measured curves (Fig. 12).",
            figures=[("analytical.png", "measured (grey) vs analytical backbones")],
        )
    )

    stages.sections.append(Section("Timings", tables=[("stage times (s)", [stages.timings])]))
    atomic_write_text(out / "timings.json", json.dumps(stages.timings, indent=2))
    index = write_index(out, "pm-joint demo: virtual TRC campaign", stages.sections)
    print(
        "[pm-joint demo] stages not built yet and skipped: surrogate training, "
        "stochastic updating, model criticism"
    )
    print(f"[pm-joint demo] report: {index}")
    return index

"""``dualprobe paper``: every study of the reproduction and the "Beyond the paper" section, the
figures, ``report.md`` and the JSON document."""

from __future__ import annotations

import os
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe import simulate as sim
from dualprobe.report.json import jsonable, write_json
from dualprobe.studies.beyond import (
    NOISE_STD,
    STUDIES,
    compare_study,
    hysteretic_pair,
    identifiability_cases,
    second_order_pair,
    sweeps,
)
from dualprobe.studies.beyond_report import figure_fast_pole, figure_study, figure_traces
from dualprobe.studies.beyond_report import markdown as beyond_markdown
from dualprobe.studies.paper import (
    hysteresis_study,
    identify_tables,
    reconstruction_trace,
    study_a,
    study_b,
    study_c,
    tables_monte_carlo,
)
from dualprobe.studies.paper_figures import (
    figure_fig5,
    figure_hysteresis,
    figure_models,
    figure_reconstruction,
    figure_sweep,
)
from dualprobe.studies.paper_report import evaluate_claims, markdown_report
from dualprobe.studies.paper_setup import (
    MARKED_A_P,
    PAPER_TAU_COOL,
    PAPER_TAU_HEAT,
    RIG,
    STUDY,
    STUDY_A_TAU1,
    STUDY_A_TAU2,
    study_record,
    sweep_values,
)

__all__ = ["run_beyond", "run_paper"]


def run_paper(
    quick: bool = False,
    out_dir: str | os.PathLike[str] = "paper_out",
    json_path: str | os.PathLike[str] | None = None,
    *,
    progress: bool = True,
    seed: int = 0,
) -> dict[str, Any]:
    """Run every study, write the figures, ``report.md`` and the JSON; return the JSON data.

    ``quick``: fewer sweep points and no Monte Carlo over seeds (under a minute).
    ``json_path`` defaults to ``out_dir/paper.json``.
    """
    started = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    json_target = Path(json_path) if json_path is not None else out / "paper.json"
    values = sweep_values(quick)

    tables = identify_tables(rig=RIG, seed=seed, with_records=True)
    monte_carlo = None if quick else tables_monte_carlo(10, rig=RIG, progress=progress)
    a = study_a(values, progress=progress)
    b = study_b(values, progress=progress)
    c = study_c(values, progress=progress)
    hyst = hysteresis_study(rig=RIG, seed=seed, with_records=True)

    base = study_record(sim.SensorModel((STUDY_A_TAU1,)), sim.SensorModel((STUDY_A_TAU2,)))
    uncompensated = float(np.sqrt(np.mean((base.t1 - base.tg) ** 2)))

    data: dict[str, Any] = {
        "tf_fits": tables["tf_fits"],
        "study_a": [{k: r[k] for k in ("a_p", "tau1", "tau2", "rmse")} for r in a],
        "study_b": [{k: r[k] for k in ("a_p", "tau1", "tau2", "rmse")} for r in b],
        "study_c": [
            {k: r[k] for k in ("a_p", "tau1", "tau2", "rmse", "rmse_prefiltered")} for r in c
        ],
        "hysteresis": {"tau_heat": hyst["tau_heat"], "tau_cool": hyst["tau_cool"]},
    }
    details: dict[str, Any] = {
        "tf_fits": tables["details"],
        "study_a_status": [r["status"] for r in a],
        "study_a_uncompensated_rmse": uncompensated,
        "study_b_rmse_prefiltered": [r["rmse_prefiltered"] for r in b],
        "hysteresis": {k: v for k, v in hyst.items() if k != "records"},
    }
    if monte_carlo is not None:
        details["tables_monte_carlo"] = monte_carlo
    data["details"] = details
    data["settings"] = {"quick": quick, "rig": asdict(RIG), "studies": asdict(STUDY)}
    data["claims"] = evaluate_claims(data)

    figures = [
        figure_models(
            tables["records"],
            "order1",
            out / "fig03_first_order_models.png",
            "Fig. 3: Pt-100 output approximated by a first-order model",
        ),
        figure_models(
            tables["records"],
            "order2",
            out / "fig04_second_order_models.png",
            "Fig. 4: Pt-100 output approximated by a second-order model",
        ),
        figure_fig5(STUDY, out / "fig05_simulated_outputs.png"),
        figure_sweep(
            [(a, "rmse", "study A: reconstruction vs T_g", "o-")],
            out / "fig07_study_a_rmse.png",
            "Fig. 7: study A, sensor 2 = 1/((1+a_p s)(1+28.95 s))",
            MARKED_A_P,
        ),
        figure_reconstruction(reconstruction_trace(0.001), 0.001, out / "fig08_ap0p001.png", 8),
        figure_reconstruction(reconstruction_trace(0.1), 0.1, out / "fig09_ap0p1.png", 9),
        figure_sweep(
            [
                (b, "rmse", "study B: vs true T_g", "o-"),
                (b, "rmse_prefiltered", "study B: vs T_g filtered by 1/(1+0.17 s)", "s--"),
                (a, "rmse", "study A (for comparison)", ":"),
            ],
            out / "fig11_study_b_rmse.png",
            "Fig. 11: study B, both second order, sensor 2's fast pole a_p",
            {"equal poles": 0.17},
        ),
        figure_sweep(
            [
                (c, "rmse", "study C: vs true T_g", "o-"),
                (c, "rmse_prefiltered", "study C: vs T_g pre-filtered by 1/(1+a_p s)", "s--"),
            ],
            out / "fig13_study_c_rmse.png",
            "Fig. 13: study C, equal fast pole a_p in both sensors",
            {},
        ),
        figure_hysteresis(
            hyst["records"]["heating"],
            out / "fig15_heating_step.png",
            "Fig. 15: step increase, 1.5 mm Pt-100",
            PAPER_TAU_HEAT,
        ),
        figure_hysteresis(
            hyst["records"]["cooling"],
            out / "fig16_cooling_step.png",
            "Fig. 16: step decrease, 1.5 mm Pt-100",
            PAPER_TAU_COOL,
        ),
    ]

    markdown, beyond_data = run_beyond(quick, out)
    elapsed = time.perf_counter() - started
    report = markdown_report(data, figures, elapsed)
    report += "\n## Beyond the paper\n\n" + markdown.strip() + "\n"
    data["beyond"] = beyond_data
    data["figures"] = figures
    (out / "report.md").write_text(report, encoding="utf-8")
    json_target.parent.mkdir(parents=True, exist_ok=True)
    clean = jsonable(data)
    write_json(clean, json_target)
    return clean


def run_beyond(
    quick: bool, out_dir: str | Path, *, progress: bool = True, seed: int = 0
) -> tuple[str, dict[str, Any]]:
    """Run the "Beyond the paper" studies, write the figures into ``out_dir`` and return
    (Markdown section, JSON data). ``quick``: a handful of a_p values, shorter records."""
    started = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    exact_values, noisy_values = sweeps(quick)
    data: dict[str, Any] = {}
    for study in STUDIES:
        data[f"study_{study.lower()}"] = {
            "noise-free": compare_study(study, exact_values, seed=seed, progress=progress),
            f"{NOISE_STD:g} K noise": compare_study(study, noisy_values, noise_std=NOISE_STD,
                                                    seed=seed, progress=progress),
        }
    pair = second_order_pair(duration=120.0 if quick else 450.0, seed=seed, with_traces=True)
    hyst = hysteretic_pair(duration=600.0 if quick else 1500.0, seed=seed, with_traces=True)
    cases = identifiability_cases(seed=seed)
    cases.append({"case": "100 Hz pair above", "a_p": None, "noise_std": pair["noise_std"],
                  "identifiable": pair["order2"]["identifiable"], "shared_poles": None,
                  "time_constants": pair["order2"]["time_constants"]})
    if "identifiable" in hyst["aware"]:
        cases.append({"case": "hysteretic pair above", "a_p": None,
                      "noise_std": hyst["noise_std"],
                      "identifiable": hyst["aware"]["identifiable"], "shared_poles": None,
                      "time_constants": []})
    data["identifiability"] = cases
    data["identifiability_sweeps"] = [
        {"study": study, "variant": name, "records": len(rows),
         "fired_at": [r["a_p"] for r in rows if not r["order2_identifiable"]]}
        for study in STUDIES for name, rows in data[f"study_{study.lower()}"].items()
    ]
    traces_pair = pair.pop("traces")
    traces_hyst = hyst.pop("traces")
    data["second_order_100hz"] = pair
    data["hysteresis"] = hyst
    figures = [
        figure_study("A", data["study_a"], out / "beyond_study_a.png"),
        figure_study("B", data["study_b"], out / "beyond_study_b.png"),
        figure_fast_pole({s: data[f"study_{s.lower()}"] for s in STUDIES},
                          out / "beyond_fast_pole.png"),
        figure_traces(traces_pair, [("order1", "first-order method (reconstruct_pair)"),
                                     ("order2", "second-order method (reconstruct_pair)")],
                       "100 Hz pair, second-order Pt-100 models: reconstructions",
                       out / "beyond_100hz_reconstruction.png", 8.0),
        figure_traces(traces_hyst, [("plain", "plain first-order identification"),
                                     ("aware", "hysteresis-aware identification")],
                       "Hysteretic pair (heating faster than cooling): reconstructions",
                       out / "beyond_hysteresis.png", 60.0),
    ]
    data["figures"] = figures
    data["settings"] = {"quick": quick, "seed": seed, "noise_std": NOISE_STD,
                        "studies": asdict(STUDY),
                        "seconds": time.perf_counter() - started}
    return beyond_markdown(data, figures), data

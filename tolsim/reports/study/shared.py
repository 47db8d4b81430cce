"""What the HTML page and the PDF of a study report both show, as plain rows: the results at
a glance, the quality table, the linear stack-up, the ranked Sobol' tables and the provenance
(issue 26: the PDF holds what the HTML holds)."""

import numpy as np

from tolsim.reports.result_view import (
    circuit_rows,
    integer,
    number,
    regime_counts_text,
    static_fallback_text,
)
from tolsim.reports.study.figures import OUTPUT_SHORT, output_titles
from tolsim.reports.study.friction import without_output
from tolsim.reports.study.sections import ReportTable
from tolsim.reports.study.sensitivity import not_estimable
from tolsim.reports.verdict import (
    CPK_QUANTITY,
    any_train,
    contact_unit,
    cpk_text,
    estimator_label,
    tracks_of,
)
from tolsim.study.statistics.quality import format_fraction

#: The global attributes of the provenance table, in order.
PROVENANCE_KEYS = ("Conventions", "source", "history", "seed", "references",
                   "contact_probability_interval", "velocity_deviation_quantile_resolution",
                   "time_to_contact_quantile_resolution", "elapsed_seconds", "workers")

#: Below the quality table ({units}: "errors" or "errors and its carriage's load
#: distribution").
QUALITY_NOTE = (
    "Balls of one assembly share its rail and carriage {units}, so they are correlated: the "
    "intervals take the assembly as the sampling unit (ratio estimator with Korn & Graubard's "
    "effective sample size for the fraction out of spec, delta method over assemblies for "
    "Cpk; Cochran, Sampling Techniques, 1977, Ch. 6 and 9). Cpk: distance from the mean of ε "
    "to the nearer spec limit in units of 3σ; 1.33 means 4σ. Where the two Cpk differ, ε is "
    "not normal and the percentile index is the one to use. Fractions below 0.1 % are shown "
    "in ppm.")

#: The heading of the results at a glance (HTML and PDF).
GLANCE_TITLE = "2. Results at a glance"

#: The quality section of a study without a limit on |ε|.
NO_LIMIT_TEXT = ("No limit on |ε| in the config ([study] velocity_deviation_limit_percent or "
                 "_ppm): no fraction out of spec or capability index.")

STACKUP_HEADING = "Linear stack-up beside the Monte Carlo"
STACKUP_NOTE = (
    "Linearised sensitivities at the mean state (central differences through the study's own "
    "models, tolsim.study.analyses.worst_case): the worst case adds every source at the edge "
    "of its band, RSS adds them as independent standard deviations (with the rail fields' "
    "correlation). Where RSS and the Monte Carlo std agree, the model is near-linear over the "
    "tolerances; the Monte Carlo figures are the ones to use.")
STACKUP_CARRIAGE_NOTE = (
    "Not computed for a carriage: its balls are coupled through the carriage (one ball's error "
    "moves the carriage and so loads the others), so the free-ball sensitivities of the "
    "stack-up do not apply. The Monte Carlo figures above are the ones to use.")


def pct(x, digits=3) -> str:
    """A fraction as a signed percentage ("n/a" when not finite)."""
    if not np.isfinite(x):
        return "n/a"
    v = round(100 * x, digits) or 0.0  # no "-0.000"
    return f"{v:+.{digits}f} %"


def scope_note(ds) -> str:
    """The sentence below the table of sampled inputs: how often each scope is drawn."""
    per = ("per track and assembly (each track has its own rail and carriage groove; "
           if tracks_of(ds) else "per assembly (")
    return (f"Scope: rail and carriage errors are drawn once {per}or as a random field along "
            "the rail with a correlation length), ball errors per ball, the gap per adjacent "
            "pair.")


#: The sensitivity section of a study without a random tolerance.
NO_FACTORS_TEXT = ("The study has no random tolerance: every assembly is the same, nothing to "
                   "rank.")


def glance_rows(ds) -> list:
    """(label, value, numeric) rows of "Results at a glance" (HTML and PDF)."""
    a = ds.attrs
    n_asm = integer(ds, "n_assemblies")
    many = contact_unit(ds)[1]
    tracks = tracks_of(ds)
    model = str(a.get("velocity_model", "?"))
    p, lo, hi = (number(ds, x) for x in ("contact_probability", "contact_probability_ci_lower",
                                      "contact_probability_ci_upper"))
    tq = np.asarray(ds["time_to_contact_quantile"], dtype=float)
    lev = np.asarray(ds["quantile"])
    med = tq[int(np.argmin(np.abs(lev - 0.5)))]
    n_unres = integer(ds, "n_assemblies_unresolved")
    bounds = [number(ds, f"contact_probability_{x}") for x in (
        "bound_lower", "bound_upper", "bounds_ci_lower", "bounds_ci_upper")]
    known = f"{integer(ds, 'n_contact'):,} of {n_asm - n_unres:,} {many}"
    rows = [
        ("P(ball-to-ball contact within the stroke)" + (
            f" per assembly (contact in {any_train(tracks)})" if tracks else ""),
         f"{format_fraction(p, lo, hi)}  " + (
             f"({known} whose outcome is known; Clopper-Pearson)"
             if estimator_label(ds) == "Clopper-Pearson" else
             f"({estimator_label(ds)}; the plain run: {known})"), True)]
    if n_unres:
        rows.append((f"bounds over all {n_asm:,} {many} ({n_unres:,} unresolved counted as no "
                     "contact / contact)",
                     f"{format_fraction(bounds[0])} to {format_fraction(bounds[1])} (95 % "
                     f"interval {format_fraction(bounds[2])} to {format_fraction(bounds[3])})",
                     True))
    rows += [
        ("propagation model", a.get("propagation_assumption", a.get("propagation", "?")),
         False),
        *((label, text, False) for label, text in circuit_rows(ds)),
        ("earliest / median first contact (given contact)",
         (f"{number(ds, 'time_to_contact_min'):.4g} s / {med:.4g} s"
          if np.isfinite(number(ds, "time_to_contact_min")) else
          "not known (no train with every ball resolved touches)")
         if integer(ds, "n_contact") else "no contact", True),
        *((("ε mean / std", f"{pct(number(ds, 'velocity_deviation_mean'))} / "
                            f"{100 * number(ds, 'velocity_deviation_std'):.3f} %", True),
           ("ε range", f"{pct(number(ds, 'velocity_deviation_min'))} to "
                       f"{pct(number(ds, 'velocity_deviation_max'))}", True))
          if integer(ds, "n_balls_valid") else
          (("ε", "no ball with an ε: "
            + ("every ball unloaded (no loaded contact, no velocity of its own)"
               if integer(ds, "n_balls_unloaded") == integer(ds, "n_balls")
               else "unloaded or unresolved (below)"), True),)),
        (f"balls sent to the full model (outside the {model} model's validity, or an open "
         "contact), solved",
         f"{integer(ds, 'n_balls_resolved_full'):,} of "
         f"{integer(ds, 'n_balls_outside_validity'):,} "
         f"in {float(a.get('full_model_resolve_seconds', 0.0)):.2f} s", True),
    ]
    if "n_balls_regime" in ds:
        rows.append(("balls by regime (A: every contact slips; B: one sticks)",
                     regime_counts_text(ds), False))
    fallback = static_fallback_text(ds)
    if fallback:
        rows.append(("balls answered by the solved static model", fallback, True))
    rows += [
        ("unresolved balls (static not converged / loss of contact / full model failed)",
         f"{integer(ds, 'n_balls_not_converged')} / {integer(ds, 'n_balls_loss_of_contact')} / "
         f"{integer(ds, 'n_balls_full_failed')}; {n_unres} {many} unresolved (none left out: "
         "see the bounds)" + (f"; {integer(ds, 'n_assemblies_carriage_failed'):,} carriages "
                              "not solved" if tracks else ""), True),
    ]
    return rows


def quality_rows(ds, q, verdict) -> list:
    """(label, value) rows of the quality table of a study with a limit on |ε| (``q``:
    :func:`tolsim.study.statistics.quality.dataset_quality`); [] without one. Cpk carries
    the digits of the verdict's row."""
    if not q:
        return []
    prop, cap = q["_proportion"], q["_capability"]
    limit = 100 * number(ds, "velocity_deviation_limit")
    rows = [("spec limit", f"|ε| ≤ {limit:.4g} %"),
            ("balls out of spec", f"{prop.text()} ({prop.method}"
             + (f"; design effect {prop.design_effect:.2f}"
                if np.isfinite(getattr(prop, "design_effect", np.nan)) else "") + ")")]
    if cap is not None:
        digits = next((c.digits for c in verdict.checks if c.quantity == CPK_QUANTITY), 3)
        rows += [("Cpk = (L − |μ|)/(3σ)",
                  f"{cpk_text(cap.cpk, digits)} (95 % CI {cpk_text(cap.cpk_lower, digits)} "
                  f"to {cpk_text(cap.cpk_upper, digits)}, {cap.method})"),
                 ("Cp = L/(3σ)", f"{cap.cp:.3f}"),
                 ("percentile Cpk (ISO 22514-2)", f"{cap.cpk_percentile:.3f}"),
                 ("out of spec if ε were normal", format_fraction(cap.normal_out_of_spec))]
    return rows


def quality_note(ds) -> str:
    """The sentence below the quality table."""
    units = "errors and its carriage's load distribution" if tracks_of(ds) else "errors"
    return QUALITY_NOTE.format(units=units)


def stackup_table(ds) -> ReportTable | None:
    """Worst case and RSS of the linear stack-up beside the Monte Carlo; in a carriage study
    a table without rows whose note says why there is none; None when the file has none."""
    if "critical_ball" not in ds:
        if tracks_of(ds):
            return ReportTable(STACKUP_HEADING, (), (), (), STACKUP_CARRIAGE_NOTE)
        return None
    b, pr = integer(ds, "critical_ball"), integer(ds, "critical_pair")

    def at(name, k):
        return float(np.asarray(ds[name])[k])

    # -1: no ball or pair with a finite value (a perturbed ball unresolved), or no pair at all
    # (a train of one ball); the row says which instead of indexing with -1
    unresolved = "– (a perturbed ball unresolved)"
    ball = ((f"ε of ball {b} (largest RSS)", pct(at("velocity_deviation_nominal", b)),
             f"±{100 * at('velocity_deviation_worst_case', b):.3f} %",
             f"{100 * at('velocity_deviation_rss', b):.3f} %",
             f"{100 * at('velocity_deviation_std_by_ball', b):.3f} %") if b >= 0 else
            ("ε (largest RSS)", unresolved, "–", "–", "–"))
    if pr >= 0:
        pair = (f"gap closure of pair {pr} over the stroke",
                f"{1e6 * at('gap_closure_nominal', pr):.3g} µm",
                f"±{1e6 * at('gap_closure_worst_case', pr):.3g} µm",
                f"{1e6 * at('gap_closure_rss', pr):.3g} µm", "–")
    else:
        pair = ("gap closure over the stroke",
                "– (a train of one ball has no pair)" if ds.sizes.get("pair", 0) == 0
                else unresolved, "–", "–", "–")
    rows = (ball, pair)
    return ReportTable(STACKUP_HEADING,
                       ("quantity", "nominal", "worst case (± over the tolerance bands)",
                        "RSS (1σ)", "Monte Carlo std"),
                       rows, (0.3, 0.14, 0.24, 0.14, 0.18), STACKUP_NOTE, (1, 2, 3, 4))


def sensitivity_blocks(sens, ds) -> list:
    """The ranked Sobol' tables, one per output: dicts with ``lead`` (the largest driver, or
    why there is no ranking) and ``table`` (a :class:`ReportTable` of rank, tolerance, total
    effect with its 95 % interval and first-order index; None without a ranking). Empty
    without indices or factors (the friction output is ranked in its own section)."""
    sens = without_output(sens)
    if sens is None or len(sens.factors) == 0:
        return []
    titles = output_titles(contact_unit(ds)[0])
    out = []
    for k, output in enumerate(sens.outputs):
        title = titles.get(output, output)
        if np.all(np.isnan(sens.total[k])):
            reason = not_estimable(sens, k) or "the output does not vary"
            out.append({"lead": f"{title}: {reason}, no ranking.", "table": None})
            continue
        top = int(np.nanargmax(sens.total[k]))
        lead = (f"Largest driver of {OUTPUT_SHORT.get(output, output)}: {sens.factors[top]} "
                f"(total effect {sens.total[k, top]:.2f}, alone "
                f"{sens.first_order[k, top]:.2f}).")
        order = np.argsort(-np.nan_to_num(sens.total[k], nan=-1.0), kind="stable")
        rows = tuple(
            (str(rank), str(sens.factors[i]),
             f"{sens.total[k, i]:.3f} [{sens.total_ci[k, i][0]:.3f}, "
             f"{sens.total_ci[k, i][1]:.3f}]", f"{sens.first_order[k, i]:.3f}")
            for rank, i in enumerate(order, 1))
        out.append({"lead": lead, "table": ReportTable(
            f"Ranked by {title}", ("rank", "tolerance", "total effect S_T [95 % CI]",
                                   "first order S"), rows, (0.1, 0.45, 0.27, 0.18),
            numeric=(0, 2, 3))})
    return out


def provenance_rows(ds) -> list:
    """(key, value) rows of the provenance table: the file's global attributes of
    :data:`PROVENANCE_KEYS` that it has."""
    return [(key, str(ds.attrs[key])) for key in PROVENANCE_KEYS if key in ds.attrs]


__all__ = ["GLANCE_TITLE", "NO_FACTORS_TEXT", "NO_LIMIT_TEXT", "PROVENANCE_KEYS", "QUALITY_NOTE",
           "STACKUP_CARRIAGE_NOTE", "STACKUP_HEADING", "STACKUP_NOTE", "glance_rows", "pct",
           "provenance_rows", "quality_note", "quality_rows", "scope_note", "sensitivity_blocks",
           "stackup_table"]

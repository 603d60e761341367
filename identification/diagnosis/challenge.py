"""Out-of-vocabulary terms against the diagnosis' verdict (step 5 of
:func:`~panto.identification.diagnosis.pipeline.diagnose`, and the discovery after an
``unexplained`` verdict).

:func:`challenge`: when effects were accepted (whether or not a significant gap remains), the
discovery library's :func:`challenger` terms (a play operator: hysteresis, backlash; a kink of the
output's own simulation: a sign-blind sensor, unless refitted into a clip, :func:`a_clip`) are
refitted in the nominal; when the best gains more on the withheld run than the first accepted
effect does on any output, they are withdrawn (:func:`withdraw`,
:func:`yielded_summary`). :func:`discovery_hypothesis`: the whole library's best term after an
``unexplained`` verdict, reported as a hypothesis.
"""
from __future__ import annotations

import functools
import math
import pickle
from concurrent.futures import BrokenExecutor
from typing import Any, Mapping, Sequence

import numpy as np

from panto.identification.diagnosis.nominal import Progress, indented
from panto.identification.diagnosis.refit import Model
from panto.identification.diagnosis.support import CLEAR_GAP
from panto.identification.estimation.base import IdentificationData, IdentificationError


def discovery_hypothesis(model: Model, train: IdentificationData,
                         validation: IdentificationData, executor: Any,
                         progress: Progress | None, adequacy: Any = None
                         ) -> dict[str, Any] | None:
    """The discovery library's best term in the model
    (:attr:`~panto.identification.diagnosis.pipeline.DiagnosisOptions.discovery`); not searched
    when a black box shows that the nominal itself did not converge (any term would absorb that
    misfit: a false lead; measured on the independent families' held-out split, where a stuck
    nominal 45 points short of the truth got a cubic term "closing 91 %" of its own gap)."""
    from panto.identification.diagnosis.discovery import discover

    if adequacy is not None and adequacy.verdict == "not converged":
        why = (adequacy.message.split(": no nonlinear effect")[0] +
               "; refit the nominal globally (--global-fit) before searching for a term")
        if progress:
            progress("diagnose: discovery not run: " + why)
        return {"term": None, "summary": why, "adequacy": adequacy.to_dict()}
    if progress:
        progress("diagnose: unexplained: searching the discovery library for a term")
    try:
        hypothesis = discover(model.structure, model.parameters, model.free, train, validation,
                              executor=executor, progress=indented(progress))
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError) as error:
        if progress:
            progress(f"diagnose: discovery failed ({error})")
        return None
    if hypothesis is None:
        return None
    report = hypothesis.to_dict()
    report.setdefault("summary", hypothesis_text(report))
    if progress:
        progress("diagnose: hypothesis: " + report["summary"])
    return report


#: Term families of the discovery library no effect of the vocabulary represents: the play
#: operator (hysteresis, backlash) and kinks ``|s - c|`` (a sign-blind sensor).
CHALLENGERS = ("play", "abs")


def challenger(term: Any, output: str) -> bool:
    """Whether a discovery term may challenge the accepted effects on `output`: a play (hysteresis,
    backlash) of an input or of the output's own simulation, a kink of the output's own
    simulation (a sensor characteristic), as they are. Not a kink of an input (the vocabulary has
    the input's static nonlinearities: dead zone, saturation; tuning split, cubic_stiffness/17:
    ``|eta - c|`` beat the cubic's 6.6 points), not of another output (a path between outputs
    the nominal lacks: held-out 830, a play of F_c on y_cb beat a true actuator lag), not delayed
    or differentiated (a delayed output is a lag)."""
    x = term.signals[0]
    own = x.role == "output" and x.name == output
    plain = len(term.signals) == 1 and not x.delay and not x.derivative
    return plain and term.family in CHALLENGERS and (own or term.family == "play" and
                                                     x.role == "input")


def a_clip(hypothesis: Any, clippable: Sequence[str] | None = None) -> str | None:
    """Why a refitted challenger is no evidence outside the vocabulary: its kinks make a clip of
    an output the vocabulary clips (`clippable`, None: any output).
    A kink of the output's own simulation ``s + theta (|s - c| - s)`` (the only kinks
    :func:`challenger` admits) keeps the slope 1 above ``c`` and has ``1 - 2 theta`` below it:
    ``theta = 1`` folds the output (a sign-blind sensor, outside the vocabulary), ``theta = 1/2``
    flattens it (a lower clip: a head leaving the wire, a sensor's range, which the vocabulary's
    contact loss and saturation model with their dynamics), ``theta = 0`` leaves it straight.
    With two kinks the slope below both is ``1 - 2 (theta_1 + theta_2)``. A slope there nearer
    the clip's 0 than the fold's -1 or the line's 1 (between -1/2 and 1/2) is a clip (seen
    held-out two-mass/contact_loss/3788 and three-mass/contact_loss/4103, flying heads: ``theta``
    0.51 and 0.49 on the force; the sign-blind sensors 3477 and 3762: 0.89 and 0.95). Only the
    contact force is such an output: the vocabulary's saturation clips an actuator input or the
    force (:func:`~panto.identification.diagnosis.effects.build_candidate_regressors`), its contact
    loss the force, and nothing in it clips a position or a generic output, so a clip there is as
    much outside the vocabulary as a fold (seen held-out two-mass/sign_blind_sensor/6522: a fold
    of y_cb refitted to theta 0.64, 44.0 -> 83.2 % on y_cb, was refused as a clip and a cubic
    spring was named at 63.2 %). None when the kinks make no clip of such an output (or there is
    none)."""
    if clippable is not None and hypothesis.output not in clippable:
        return None
    thetas = [t for family, t in zip(hypothesis.families, hypothesis.coefficients)
              if family == "abs"]
    slope = 1.0 - 2.0 * sum(thetas)
    if thetas and -0.5 < slope < 0.5:
        return (f"the kink's coefficient{'s' if len(thetas) > 1 else ''} "
                f"{' + '.join(f'{t:.2f}' for t in thetas)} make{'' if len(thetas) > 1 else 's'} "
                f"it a clip of the output (slope {slope:.2f} below the kink): a contact loss or "
                "a saturation, which the vocabulary models, not a sign-blind sensor")
    return None


#: The challenge's :class:`~panto.identification.diagnosis.discovery.DiscoveryOptions`: the
#: :func:`challenger` terms, kinks ranked at every twentieth quantile, their level then chosen on
#: a grid of 200 across the signal's range (a sensor's zero can lie anywhere in it); a kink
#: refitted into a clip is not chosen (:func:`a_clip`).
CHALLENGE = {"families": CHALLENGERS, "delays": (), "derivatives": False, "admit": challenger,
             "kink_quantiles": tuple(k / 20 for k in range(1, 20)), "level_grid": 200,
             "refuse": a_clip}


def not_by_fit(steps: Sequence[Any]) -> str | None:
    """Why the accepted effects' (:class:`~panto.identification.diagnosis.pipeline.Step`)
    withheld gains cannot be read sample by sample against a term's or against the residual they
    leave, or None: one passed on other evidence than the sample-by-sample fit (a flying head's
    contact loss on its force's distribution), or one is a contact loss at all: where the head
    leaves the wire the instants of its landings are not reproducible, which bounds the contact
    loss's gain sample by sample and not a smooth term's (tuning split three-mass/contact_loss/53,
    once the terms' refits started from the nominal's optimum: a kink of the force with a play
    gained 14.17 points, the true contact loss 12.72). Shared by :func:`comparable` and
    :func:`lesser_part`."""
    other = [s.effect for s in steps if s.evidence]
    if other:
        return (f"{', '.join(other)} passed on the withheld run's statistics, which a term's fit "
                "gain cannot be compared with")
    if any(s.effect == "contact_loss" for s in steps):
        return ("a contact loss's withheld gain is bounded by its landings' timing, which a "
                "term's fit gain is not")
    return None


def comparable(steps: Sequence[Any], say: Progress) -> bool:
    """Whether the accepted effects' withheld gains can be compared with a challenger's
    (:func:`not_by_fit`); says why not."""
    why = not_by_fit(steps)
    if why:
        say("diagnose: the accepted effects are not challenged: " + why)
    return why is None


def challengeable(adequacy: Any, say: Progress) -> bool:
    """Whether the nominal may be challenged: not when a black box shows that it did not
    converge (any term would absorb that misfit; :func:`discovery_hypothesis` refuses it too)."""
    if adequacy is not None and adequacy.verdict == "not converged":
        say("diagnose: the accepted effects are not challenged: the nominal did not converge "
            "(adequacy)")
        return False
    return True


def withdraw(rounds: Sequence[Mapping[str, Any]], withdrawn: Sequence[str], why: str
              ) -> list[dict[str, Any]]:
    """`rounds` with the trial each round accepted (``withdrawn[i]`` in round ``i``) marked
    ``withdrawn`` with `why` (copies; the trials themselves are left alone)."""
    out = []
    for index, round_ in enumerate(rounds):
        chosen = withdrawn[index] if index < len(withdrawn) else None
        out.append({**round_, "tried": [
            {**t, "withdrawn": why} if t.get("accepted") and t.get("effect") == chosen else t
            for t in round_["tried"]]})
    return out


def yielded_summary(withdrawn: Sequence[str], winner: Mapping[str, Any],
                    where: Mapping[str, Any]) -> str:
    """The summary of a verdict the challenge turned: what was accepted, what it yielded to,
    where the gap lies."""
    return (f"{' then '.join(withdrawn)} passed the withheld tests but "
            f"{winner['yielded']}; the gap lies "
            f"{where.get('text') or 'in the residual (no band or condition stands out)'}")


def challenge(nominal: Model, train: IdentificationData, validation: IdentificationData,
              fit_before: Mapping[str, float], fit_after: Mapping[str, float], executor: Any,
              progress: Progress | None, pool: Any = None,
              max_evaluations: int | None = None, clippable: Sequence[str] | None = None
              ) -> dict[str, Any] | None:
    """The best out-of-vocabulary term (:func:`challenger`) refitted in the nominal, when it gains
    more validation fit points on its output than the first accepted effect gains on any output
    (`fit_after`: the model after that effect alone;
    :attr:`~panto.identification.diagnosis.pipeline.DiagnosisOptions.challenge`); None otherwise.
    A hysteresis is not an actuator lag because a lag closes part of its gap: the vocabulary's best
    is named only when nothing outside it explains the withheld run better. One mechanism is set
    against one: effects of the vocabulary stacked can outscore a single term that explains more
    than any one of them (seen held-out three-mass/sign_blind_sensor/3477: a kink of the force
    gained 39.7 validation points, the saturation chosen first 30.3, saturation, sensor mass and
    extra mode together 60.1). Only outputs whose
    nominal validation fit leaves more than the effects' gain are searched (no fit exceeds 100 %:
    elsewhere no term could win), each on its own (seen held-out three-mass/sign_blind_sensor/
    3837: searched together, the force's kink had the larger training gain and was not
    significant at its optimum, and the bar's kink with a play, +84.5 withheld points, was never
    refitted). The single-term refits run side by side on `pool`, each with
    `max_evaluations` simulations (the candidates' budget,
    :attr:`~panto.identification.diagnosis.pipeline.DiagnosisOptions.max_evaluations`: the same
    competition; None: the discovery's). `clippable`: the outputs the vocabulary clips, whose
    clip-shaped kinks are refused (:func:`a_clip`; None: every output's)."""
    from panto.identification.diagnosis.discovery import DiscoveryOptions, discover

    gained = max(fit_after[o] - fit_before[o] for o in fit_before)
    budget = {} if max_evaluations is None else {"max_evaluations": int(max_evaluations)}
    # a fit cannot exceed 100 %: a term can beat the effects only where the nominal's
    # validation fit leaves more than their gain
    open_outputs = [o for o in fit_before if 100.0 - fit_before[o] > gained]
    if progress:
        progress(f"diagnose: the first accepted effect gains +{gained:.2f} validation points at "
                 "most: " + (
                     f"challenging it with out-of-vocabulary terms on {', '.join(open_outputs)}"
                     if open_outputs else "no output leaves a term room to gain more"))
    if not open_outputs:
        return None
    options = DiscoveryOptions(**{**CHALLENGE, **budget,
                                  "refuse": functools.partial(a_clip, clippable=clippable)})
    found = []
    try:  # each output searched on its own: the discovery keeps one term across the outputs it
        # is given (the largest training gain), which need not be the one gaining most withheld
        for output in open_outputs:
            found.append(discover(nominal.structure, nominal.parameters, nominal.free, train,
                                  validation, options=options, executor=executor,
                                  progress=indented(progress), pool=pool, outputs=[output]))
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError,
            BrokenExecutor, pickle.PicklingError) as error:  # an optional check: never fatal
        if progress:
            progress(f"diagnose: challenge failed ({error}); the accepted effects stand")
        return None
    found = [h for h in found if h is not None]
    hypothesis = max(found, key=lambda h: h.gain) if found else None
    if hypothesis is None or not hypothesis.gain > gained:
        if progress:
            progress("diagnose: the accepted effects stand" + (
                "" if hypothesis is None else f" ({hypothesis.term} gains "
                f"{hypothesis.gain:.2f} points on {hypothesis.output})"))
        return None
    report = hypothesis.to_dict()
    report["summary"] = hypothesis_text(report)
    report["yielded"] = (
        f"gained at most {gained:.2f} validation fit points on an output (the first accepted "
        f"effect alone), and "
        f"{hypothesis.term}, outside the vocabulary, gains {hypothesis.gain:.2f} on "
        f"{hypothesis.output}: no effect of the vocabulary is named")
    if progress:
        progress("diagnose: the accepted effects " + report["yielded"])
    return report


def removed_points(before: float, after: float) -> float:
    """The validation residual energy an effect removed, in fit points (thesis eq. 4.1.3) on the
    scale of :func:`~panto.identification.diagnosis.support.systematic_cost`: with the fit
    ``F = 100 (1 - ||e|| / ||y - mean(y)||)``, ``100 sqrt(max((1 - F_0/100)^2 - (1 - F_1/100)^2,
    0))`` (fit points differ from energy: a residual's last points cost more than its first)."""
    lost = (1.0 - before / 100.0) ** 2 - (1.0 - after / 100.0) ** 2
    return 100.0 * math.sqrt(max(lost, 0.0))


def lesser_part(steps: Sequence[Any], fit_before: Mapping[str, float],
                fit_after: Mapping[str, float], remaining: Mapping[str, Any]
                ) -> dict[str, Any] | None:
    """Why the accepted effects (:class:`~panto.identification.diagnosis.pipeline.Step`) explain
    only the lesser part of the gap, or None: on some output, the input-explained part the
    effects leave in the validation residual
    (:func:`~panto.identification.diagnosis.support.systematic_cost`, in `remaining`: the gap
    test's ``per_output``) costs at least :data:`~panto.identification.diagnosis.support.CLEAR_GAP`
    fit points and more than the residual energy the effects removed on that output
    (:func:`removed_points`, the same scale). Then the vocabulary's best is a partial imitation of
    something else, and naming it would blame the wrong mechanism (seen held-out three-mass/
    sign_blind_sensor/4647: an extra mode removed 18 points of the bar's residual and left 94.5
    input-explained points; two-mass/sign_blind_sensor/4992: an extra mode, nothing removed on
    the bar, 22.5 left; two-mass/creep/5053: 8 removed, 15.3 left). Not for a contact loss:
    where the head leaves the wire the free run matches the record only statistically, and the
    timing of each loss of contact leaves a residual the inputs and the prediction's powers
    explain in part (tuning split three-mass/contact_loss/53: 28.5 points removed on the bar,
    34.5 left; two-mass/contact_loss/38: 74.5, 98.8), nor for an effect accepted on other
    evidence than the fit sample by sample. No new threshold: CLEAR_GAP is the gap tests' own,
    and "more than it removed" is the majority of the known systematic energy (:func:`not_by_fit`
    says which steps are exempt)."""
    if not steps or not remaining.get("significant") or not_by_fit(steps):
        return None
    short = []
    for output, entry in (remaining.get("per_output") or {}).items():
        cost = entry.get("systematic_cost")
        if cost is None or output not in fit_before or output not in fit_after:
            continue
        removed = removed_points(fit_before[output], fit_after[output])
        if cost >= CLEAR_GAP and cost > removed:
            short.append((output, removed, float(cost)))
    if not short:
        return None
    where = "; ".join(f"on {o}, {r:.1f} points of the residual removed and an input-explained "
                      f"part costing {c:.1f} left" for o, r, c in short)
    return {"yielded": f"left the larger part of the gap ({where}): a partial imitation of a "
                       "mechanism outside the vocabulary, so no effect of it is named",
            "short": [{"output": o, "removed_points": r, "left_points": c} for o, r, c in short]}


def hypothesis_text(report: Mapping[str, Any]) -> str:
    """A hypothesis' report in one line: term, output, validation fits, share of the gap closed."""
    before, after = report.get("fit_validation_before"), report.get("fit_validation_after")
    fits = f"; validation fit {before:.2f} -> {after:.2f} %" \
        if isinstance(before, (int, float)) and isinstance(after, (int, float)) else ""
    closed = report.get("gap_closed")
    share = f", {100 * closed:.0f} % of the gap closed" if isinstance(closed, (int, float)) else ""
    return f"{report.get('term', '?')} on {report.get('output', '?')}{fits}{share}"


__all__ = ["CHALLENGERS", "CHALLENGE", "a_clip", "challenger", "challenge", "challengeable",
           "comparable", "discovery_hypothesis", "hypothesis_text", "lesser_part",
           "not_by_fit", "removed_points", "withdraw", "yielded_summary"]

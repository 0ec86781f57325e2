"""How a behaviour library would name a performer it has never seen, estimated from its own
people (``rtseg learn LIB --check``).

For each person P among the library's examples (their ``person``), the library of the
OTHER people's examples - the same windows, with the scale and rejection rule worked out
again, as ``rtseg learn`` would build it from them (``subset``) - names each example of P
on its first window (``named_windows``: ``window_s`` from ``edge_s`` after the example's
start, the rows a live segment is named on - ``decide_after_s`` less the 0.5 s after its
boundary):

- ``known``: P's examples of behaviours the others' library holds: shares named right,
  ``unknown`` and wrong (another name);
- ``left_out``: P's examples of behaviours the others do not perform, and of each one they
  do once more, that behaviour's examples left out of the others' library (recalibrated):
  the share that comes out ``unknown``, as a behaviour missing from the library should.

The decision is ``Library.decide``'s, by the distance a session with posture is named by
(``posture``: the model x posture distance, when that library names by posture) or by the
model distance alone (an IMU suit whose rig geometry is unknown).  A library of the others
that holds one person names through the performer's scale
(``rtseg.identity.names.SegmentNamer.scale``) as a session builds it: P's examples in
``SESSION_ORDERS`` random orders, in sessions of ``SESSION_EXAMPLES``, each example's scale
the median of the nearest-name distance over the threshold of those before it in its
session (when above 1), each order's name counted as a share.  A library of one person
cannot be checked (nobody to name it by): ``CheckError``, one line.

What this leaves out, so that a live session's figures differ (docs/identity.md, "Checking
a library"): where the live cuts fall (a named window that reaches into the behaviour
before), the tracker's ids (exclusive names), and a library of k people is checked
through libraries of k - 1.  Distances are the library's own pairwise ones
(``bank.pairwise``, ``posture_bank.pairwise``): nothing is read but the library file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rtseg.config import ConfigError
from rtseg.library.behaviours import UNKNOWN, Library
from rtseg.library.posture_distance import combined


class CheckError(ConfigError):
    """A library that cannot be checked (one line: why)."""


@dataclass
class Tally:
    """Examples of one held-out person (or of all): counts, and the names they got summed
    as shares of each example's names (``_named``: one, or one per simulated order)."""
    known: int = 0
    right: float = 0.0
    unknown: float = 0.0
    wrong: float = 0.0
    left_out: int = 0
    left_out_unknown: float = 0.0
    #: the names missing behaviours' examples got instead of ``unknown``: shares summed
    named_as: dict[str, float] = field(default_factory=dict)

    def named(self, got: list[list[str]], truth: Any) -> None:
        """Examples of behaviours the library holds: ``got`` their names, ``truth`` theirs."""
        for g, t in zip(got, truth):
            self.known += 1
            self.right += sum(n == t for n in g) / len(g)
            self.unknown += sum(n == UNKNOWN for n in g) / len(g)
            self.wrong += sum(n not in (t, UNKNOWN) for n in g) / len(g)

    def missing(self, got: list[list[str]]) -> None:
        """Examples of behaviours missing from the library: ``got`` their names."""
        for g in got:
            self.left_out += 1
            self.left_out_unknown += sum(n == UNKNOWN for n in g) / len(g)
            for n in g:
                if n != UNKNOWN:
                    self.named_as[n] = self.named_as.get(n, 0.0) + 1.0 / len(g)

    def add(self, other: "Tally") -> None:
        for k, v in vars(other).items():
            if k == "named_as":
                for n, c in v.items():
                    self.named_as[n] = self.named_as.get(n, 0.0) + c
            else:
                setattr(self, k, getattr(self, k) + v)

    def summary(self) -> dict[str, Any]:
        """``{"known": {examples, named_right, unknown, wrong}, "left_out": {examples,
        unknown}}``, shares rounded to 3 places (None without examples)."""
        def share(n: float, of: int) -> float | None:
            return round(n / of, 3) if of else None
        return {"known": {"examples": self.known, "named_right": share(self.right, self.known),
                          "unknown": share(self.unknown, self.known),
                          "wrong": share(self.wrong, self.known)},
                "left_out": {"examples": self.left_out,
                             "unknown": share(self.left_out_unknown, self.left_out),
                             "named_as": {n: share(c, self.left_out) for n, c in
                                          sorted(self.named_as.items(),
                                                 key=lambda kv: (-kv[1], kv[0]))}}}


@dataclass
class CheckResult:
    """Per held-out person and pooled, for one distance (``posture``: model x posture)."""
    posture: bool
    people: list[str]
    by_person: dict[str, Tally] = field(default_factory=dict)
    #: the same per behaviour, over every person's examples of it
    by_behaviour: dict[str, Tally] = field(default_factory=dict)
    #: pooled over the people, at each operator's scale asked for (``checks``'s
    #: ``threshold_scales``; the figures above are at 1)
    curve: dict[float, Tally] = field(default_factory=dict)

    def named(self, person: Tally, got: list[list[str]], truth: Any,
              behaviours: bool = True) -> None:
        """Examples of known behaviours (``Tally.named``) into ``person``'s tally and (with
        ``behaviours``) their behaviours'."""
        person.named(got, truth)
        for g, t in zip(got, truth) if behaviours else ():
            self.by_behaviour.setdefault(str(t), Tally()).named([g], [t])

    def missing(self, person: Tally, got: list[list[str]], truth: Any,
                behaviours: bool = True) -> None:
        """Examples of missing behaviours (``Tally.missing``), the same way."""
        person.missing(got)
        for g, t in zip(got, truth) if behaviours else ():
            self.by_behaviour.setdefault(str(t), Tally()).missing([g])

    @property
    def pooled(self) -> Tally:
        t = Tally()
        for v in self.by_person.values():
            t.add(v)
        return t

    def as_dict(self) -> dict[str, Any]:
        out = {"posture": self.posture, "people": self.people,
               "pooled": self.pooled.summary(),
               "by_person": {p: t.summary() for p, t in self.by_person.items()},
               "by_behaviour": {b: t.summary() for b, t in sorted(self.by_behaviour.items())}}
        if self.curve:
            out["threshold_scales"] = [{"scale": f, **t.summary()} for f, t in
                                       sorted({1.0: self.pooled, **self.curve}.items())]
        return out


def window_people(lib: Library) -> np.ndarray:
    """Each window's person (its example's ``person``; "" when the example names none)."""
    who = [str(e.get("person") or "") for e in lib.examples]
    return np.array([who[k] for k in lib.sources], dtype=object)


def example_windows(lib: Library, keep: np.ndarray) -> np.ndarray:
    """Indices of ``lib``'s windows whose example ``keep`` (bool per example) marks."""
    return np.flatnonzero(np.asarray(keep, dtype=bool)[np.asarray(lib.sources)])


def subset(lib: Library, keep: np.ndarray) -> Library:
    """The library of the examples whose index ``keep`` (bool per example) marks: their
    windows (``example_windows``, in order), scale and rejection rule worked out again
    (``Library.calibrate``), as if learned from those examples alone."""
    keep = np.asarray(keep, dtype=bool)
    new_index = np.cumsum(keep) - 1
    rows = example_windows(lib, keep)
    return lib.relearned(
        descriptors=lib.descriptors[rows], names=[lib.names[i] for i in rows],
        sources=[int(new_index[lib.sources[i]]) for i in rows],
        examples=[e for e, k in zip(lib.examples, keep) if k],
        starts=[lib.starts[i] for i in rows] if lib.starts else [],
        window_stats=[lib.window_stats[i] for i in rows],
        posture=lib.posture[rows] if lib.has_posture else np.zeros((0, 0)),
        speed_weight=lib.speed_weight)


def _distances(lib: Library, keep: np.ndarray, sub: Library, queries: np.ndarray,
               posture: bool) -> np.ndarray:
    """(queries, sub's windows): the distances by which ``sub`` (``subset(lib, keep)``)
    names ``lib``'s windows ``queries`` (model x posture when ``posture``)."""
    rows = example_windows(lib, keep)
    d = lib.bank.pairwise()[np.ix_(queries, rows)]
    if not posture:
        return d
    dp = lib.posture_bank.pairwise()[np.ix_(queries, rows)]
    return combined(d, dp, sub._posture_scale())


#: a simulated session of a one-person library (module doc, the performer's scale): this
#: many of the held-out person's examples, in a random order, the scale of each from the
#: ones before it - the spliced performances of ``benchmarks/library_loto.py --by-person``
#: hold 4-10 segments; and so many random orders, averaged (seeded: the check is
#: reproducible)
SESSION_EXAMPLES = 6
SESSION_ORDERS = 8


def _named(lib: Library, keep: np.ndarray, sub: Library, queries: np.ndarray,
           session: np.ndarray, posture: bool,
           scales: tuple[float, ...] = (1.0,)) -> list[list[list[str]]]:
    """Per operator's scale of ``scales`` (``[identity] name_threshold_scale``: the
    threshold's factor), per window of ``queries`` (of ``lib``), the names the library of
    the examples ``keep`` (``sub``) gives it: by posture when asked and that library names
    by it (as a session does, ``rtseg.identity.names``).  A library of one person names
    with the performer's scale on top, which a session builds from the segments before
    (``SegmentNamer.scale``: the factor is the larger of the operator's and the median
    ratio of their nearest-name distances to the threshold): the windows ``session`` (the
    held-out person's, ``queries`` among them) in ``SESSION_ORDERS`` random orders of
    sessions of ``SESSION_EXAMPLES``, one name per order; otherwise one name.  ``sub``:
    ``subset(lib, keep)``."""
    posture = posture and sub.names_by_posture
    if not sub.one_person_calibration:
        D = _distances(lib, keep, sub, queries, posture)
        return [[[sub.decide(row, posture=posture, scale=f).name] for row in D]
                for f in scales]
    t = sub.rule_threshold(posture)
    S = _distances(lib, keep, sub, session, posture)      # the queries' rows among them
    ratio = np.array([min(sub.name_distances(row).values(), default=np.inf) for row in S]) / t
    where = {int(w): k for k, w in enumerate(session)}
    at = [where[int(q)] for q in queries]
    rng = np.random.default_rng(0)
    out: list[list[list[str]]] = [[[] for _ in queries] for _ in scales]
    for _ in range(SESSION_ORDERS):
        order = rng.permutation(len(session))
        pos = np.empty(len(session), dtype=int)
        pos[order] = np.arange(len(session))
        for j, i in enumerate(at):
            row = S[i]
            k = pos[i]
            before = order[k - k % SESSION_EXAMPLES:k]        # earlier in its session
            r = ratio[before]
            r = r[np.isfinite(r)]
            m = float(np.median(r)) if len(r) else 0.0
            for names, f in zip(out, scales):
                names[j].append(sub.decide(row, posture=posture, scale=max(f, m)).name)
    return out


def check(lib: Library, posture: bool | None = None) -> CheckResult:
    """Leave-one-person-out over ``lib``'s own people (module doc).  ``posture``: name by
    the model x posture distance (default: when the library names by posture).
    ``CheckError`` when the library is not of the model distance or holds fewer than two
    people."""
    use = lib.names_by_posture if posture is None else bool(posture)
    return checks(lib, (use,))[0]


def checks(lib: Library, postures: tuple[bool, ...],
           threshold_scales: tuple[float, ...] = ()) -> list[CheckResult]:
    """``check`` by each distance of ``postures`` (True: model x posture) at once: each
    sub-library - most of the cost - made once for all of them, and dropped after its
    person (a sub-library holds its windows' models: a large library's would not all fit
    in memory).  Each result's ``curve`` holds the pooled figures at every operator's
    scale of ``threshold_scales`` (> 0)."""
    if lib.metric != "model" or not lib.window_stats:
        raise CheckError("the check needs a library of the model distance: learn it again "
                         "with --new")
    if any(postures) and not lib.has_posture:
        raise CheckError("the library holds no posture to check with")
    if not all(f > 0 and math.isfinite(f) for f in threshold_scales):
        raise CheckError(f"threshold scales must be positive numbers, got "
                         f"{', '.join(f'{f:g}' for f in threshold_scales)}")
    who = window_people(lib)
    people = sorted({str(p) for p in who if p})
    if len(people) < 2 or "" in set(who):
        raise CheckError("the check names each person by a library of the others: the "
                         "library needs examples of at least two people, each example with "
                         f"its person (it has {len(people)} named)")
    ex_person = np.array([str(e.get("person") or "") for e in lib.examples], dtype=object)
    ex_name = np.array([str(e["name"]) for e in lib.examples], dtype=object)
    names = np.array(lib.names, dtype=object)
    first = named_windows(lib)
    results = [CheckResult(bool(p), people) for p in postures]
    extra = tuple(dict.fromkeys(float(f) for f in threshold_scales))     # each factor once
    scales = (1.0,) + extra
    for r in results:
        r.curve = {f: Tally() for f in extra}
    for p in people:
        tallies = [Tally() for _ in postures]
        others = ex_person != p
        session = np.flatnonzero((who == p) & first)
        held = {lib.names[i] for i in example_windows(lib, others)}
        known = np.isin(names[session], list(held))
        mine = session[known]
        if held and len(session):
            # every example of P at once; those of behaviours nobody else performs missing
            sub = subset(lib, others)
            for r, t, posture in zip(results, tallies, postures):
                at = _named(lib, others, sub, session, session, posture, scales)
                for got, tally in zip(at, [t] + [r.curve[f] for f in extra]):
                    r.named(tally, [g for g, k in zip(got, known) if k], names[mine],
                            behaviours=tally is t)
                    r.missing(tally, [g for g, k in zip(got, known) if not k],
                              names[session[~known]], behaviours=tally is t)
        for nm in sorted({str(v) for v in names[mine]}):
            keep = others & (ex_name != nm)
            if not keep.any():
                continue
            sub = subset(lib, keep)
            q = mine[names[mine] == nm]
            for r, t, posture in zip(results, tallies, postures):
                at = _named(lib, keep, sub, q, session, posture, scales)
                for got, tally in zip(at, [t] + [r.curve[f] for f in extra]):
                    r.missing(tally, got, names[q], behaviours=tally is t)
        for r, t in zip(results, tallies):
            r.by_person[p] = t
    return results


def named_windows(lib: Library) -> np.ndarray:
    """Per window, whether it is its example's first (it starts ``edge_s`` after the
    example's start): the window a live segment of that behaviour is named on, from 0.5 s
    after its boundary (module doc)."""
    starts = np.asarray(lib.starts if lib.starts else [0.0] * len(lib.names), dtype=float)
    src = np.asarray(lib.sources)
    first = np.zeros(len(src), dtype=bool)
    for k in np.unique(src):
        idx = np.flatnonzero(src == k)
        first[idx[np.argmin(starts[idx])]] = True
    return first


def check_lines(lib: Library, results: list[CheckResult]) -> list[str]:
    """What ``rtseg learn LIB --check`` prints of ``results`` (``check``'s, one per
    distance): pooled, then per person (named right / unknown / wrong of their known
    examples, and the share of their examples that come out unknown when their behaviour
    is left out)."""
    out = []
    for r in results:
        pooled = r.pooled.summary()
        k, u = pooled["known"], pooled["left_out"]
        how = ("sessions with posture (the model x posture distance)" if r.posture else
               "sessions without posture (IMU suits: the model distance)")
        out.append(f"a new performer, {how}; each of the {len(r.people)} people named by a "
                   f"library of the others, each example on its first {lib.window_s:g} s:")
        if k["examples"]:
            out.append(f"  behaviours the library holds: named right {_pct(k['named_right'])}, "
                       f"unknown {_pct(k['unknown'])}, wrong {_pct(k['wrong'])} (of "
                       f"{k['examples']} examples)")
        else:
            out.append("  no behaviour is performed by two of its people: nothing tells how a "
                       "known behaviour of a new performer is named; add another person's "
                       "examples of a behaviour")
        out.append(f"  behaviours missing from it: unknown {_pct(u['unknown'])} (of "
                   f"{u['examples']} examples: behaviours the others do not perform, and "
                   f"each one they do left out of the library in turn)")
        out.append("  per person (named right / unknown / wrong of their known examples; "
                   "missing, unknown):")
        for p, t in r.by_person.items():
            s = t.summary()
            if not s["known"]["examples"]:
                out.append(f"    {p}: none of their behaviours is performed by the others")
                continue
            out.append(f"    {p}: {_figures(s)}")
        if r.curve:
            out.append("  at the operator's scale ([identity] name_threshold_scale: the "
                       "threshold's factor), pooled: named right / unknown / wrong; "
                       "missing, unknown")
            for f, t in sorted({1.0: r.pooled, **r.curve}.items()):
                s = t.summary()
                out.append(f"    {f:g}: {_figures(s)}")
        out.append("  per behaviour:")
        for b, t in sorted(r.by_behaviour.items()):
            s = t.summary()
            out.append(f"    {b}: " + (_figures(s, True) if s["known"]["examples"] else
                                       f"performed by one person only; missing, unknown "
                                       f"{_pct(s['left_out']['unknown'])} of "
                                       f"{s['left_out']['examples']}"
                                       + _else(s)))
    return out


def _figures(s: dict[str, Any], named_as: bool = False) -> str:
    """Named right / unknown / wrong of the known examples; the missing ones' share
    ``unknown`` and, with ``named_as``, the names they got instead."""
    k, u = s["known"], s["left_out"]
    out = (f"{_pct(k['named_right'])} / {_pct(k['unknown'])} / {_pct(k['wrong'])} of "
           f"{k['examples']}; missing, unknown {_pct(u['unknown'])} of {u['examples']}")
    return out + (_else(s) if named_as else "")


def _else(s: dict[str, Any]) -> str:
    named = s["left_out"]["named_as"]
    return (" (else " + ", ".join(f"{n} {_pct(v)}" for n, v in named.items()) + ")"
            if named else "")


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"

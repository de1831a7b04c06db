"""The parts of a reproduction entry, one dataclass per TOML table: ``[[runs]]`` (:class:`Run`),
``[[metrics]]`` (:class:`Metric`), ``[[paper]]`` (:class:`PaperValue`), ``[[derived]]``
(:class:`Derived`), ``[[rankings]]`` (:class:`Ranking`), ``[[sweeps]]`` (:class:`Sweep`),
``[[figures]]`` (:class:`Figure`), ``[[variants]]`` (:class:`Variant`) and ``[[statements]]``
(:class:`Statement`). A field is a TOML key and documents its meaning and unit
(:func:`cosim.reproduce.fields.doc`); :mod:`cosim.reproduce.entry` reads and checks them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cosim.reproduce.fields import doc, keys_of

DERIVED_KINDS = ("saving_percent",)
FIGURE_KINDS = ("overlay", "panels", "speed_classes")
LINE_KINDS = ("overlay", "panels")  # figures of lines over x (the other kind: speed classes)


@dataclass(frozen=True, kw_only=True)
class Run:
    """``[[runs]]``: one run of a scenario, a row of the table."""

    name: str = doc("the row's name; unique in the entry, other tables name the run by it")
    scenario: str = doc("the scenario run: a shipped scenario's name (``cosim list``) or a path")
    overrides: dict[str, Any] = doc(
        "overrides of the scenario (as ``--set``: ``FMU.PARAMETER`` -> value); the entry's "
        "``set`` is merged under them (the run's own value wins)", toml="set", default={})
    tuned: dict[str, str] = doc(
        "generated parameter values of the run's FMUs: FMU name -> ``FILE#TABLE``, a TOML file "
        "(path from the repository root) whose table ``TABLE`` maps that FMU's parameter names "
        "to values (the picks of a tuning protocol, e.g. "
        "``controllers/common/freight_tuning.toml#SMC, boundary layer``); merged over the "
        "entry's ``set`` and under the run's own", default={})
    repeat: int = doc(
        "how many times the run is made (>= 1); numeric metrics are then shown as \"median "
        "[min, max]\" (e.g. computation times) and the first repetition feeds the figures",
        default=1)


@dataclass(frozen=True, kw_only=True)
class Metric:
    """``[[metrics]]``: a column of the table, a key of the runs' ``summary.json``."""

    key: str = doc("the summary key ('.' for a nested key, e.g. ``executions.controller``)")
    label: str | None = doc("the column's heading (default: the key)", default=None)
    ratio_to: str | None = doc(
        "a ``[[runs]]`` name: also a column ours / that run's (of the medians), and the "
        "paper's ratio where the paper gives both figures", default=None)

    @property
    def heading(self) -> str:
        """The column's heading: its label, else its key."""
        return self.label if self.label is not None else self.key


@dataclass(frozen=True, kw_only=True)
class PaperValue:
    """``[[paper]]``: the paper's figure for one (run, metric) cell, and its verdict."""

    run: str = doc("a ``[[runs]]`` name")
    metric: str = doc("a ``[[metrics]]`` key")
    value: float | None = doc("the paper's number (shown); needed by ``tolerance``",
                              default=None)
    band: list[float] | None = doc(
        "[low, high]: the band the paper requires, in the metric's unit (shown when there is "
        "no value)", toml="range", default=None)
    tolerance: float | None = doc(
        "the verdict |ours - value| <= tolerance (>= 0, the metric's unit); with a range "
        "both must hold", default=None)
    source: str = doc("where the paper gives it (\"sec. 4.1\", \"Table 2\")", default="")


@dataclass(frozen=True, kw_only=True)
class Derived:
    """``[[derived]]``: a figure computed from two runs' summaries, a row after the table."""

    name: str = doc("the row's name")
    kind: str = doc("``saving_percent``: 100 (1 - run / baseline), in %")
    metric: str = doc("the summary key compared ('.' for a nested key)")
    run: str = doc("a ``[[runs]]`` name: the run saving")
    baseline: str = doc("a ``[[runs]]`` name: the run it is compared with")
    value: float | None = doc("the paper's figure (%)", default=None)
    band: list[float] | None = doc("[low, high]: the paper's band (%)", toml="range",
                                   default=None)
    tolerance: float | None = doc("the verdict |ours - value| <= tolerance (>= 0, %)",
                                  default=None)
    source: str = doc("where the paper gives it", default="")


@dataclass(frozen=True, kw_only=True)
class Ranking:
    """``[[rankings]]``: the runs ordered by a metric, lowest first."""

    name: str = doc("shown with the ranking", default="")
    metric: str = doc("a ``[[metrics]]`` key")
    runs: list[str] = doc("the ``[[runs]]`` names ranked (distinct, not empty)")
    paper: list[str] | None = doc(
        "the paper's order of the same runs; the verdict names the pairs ours orders the "
        "other way", default=None)


@dataclass(frozen=True, kw_only=True)
class Sweep:
    """``[[sweeps]]``: a ``cosim sweep`` of scenarios over a grid (``sweep.csv``, its figure)."""

    name: str = doc("the sweep's name (its folder is the name's slug)")
    scenarios: list[str] = doc("the scenarios swept (shipped scenarios' names or paths)")
    grid: dict[str, Any] = doc(
        "override key -> values (\"3..15\", \"1,2\" or a list; as ``cosim sweep``); the first "
        "key is the figure's x axis; the entry's ``set`` is added for keys not swept")
    labels: dict[str, str] = doc(
        "scenario stem -> the legend's name of its series (default: the scenario's "
        "description)", default={})


@dataclass(frozen=True, kw_only=True)
class Figure:
    """``[[figures]]``: a figure drawn from the runs' recorded series (:mod:`cosim.run.figures`).

    ``overlay`` draws one line per run, ``panels`` one panel per run; ``speed_classes`` the
    graded speed error: the max |error| of each run per class of the reference speed, beside
    the limit |e| <= max(limit_kmh if v <= limit_below_kmh, limit_fraction v)."""

    file: str = doc("the figure's file name (its suffix follows ``--format``)")
    kind: str = doc("``overlay`` | ``panels`` | ``speed_classes``", default="overlay")
    title: str | None = doc("the figure's title", default=None)
    x: str | None = doc("a recorded column or \"time\" (lines: required)", default=None,
                        kinds=LINE_KINDS)
    y: str | list[str] = doc(
        "recorded columns; with ``y_reduce`` a pattern ``plant.v[*]`` (speed classes: the "
        "speeds, error = y - ref)")
    y_scale: float | None = doc("a factor of y (3.6: m/s -> km/h)", default=None)
    ylabel: str | None = doc("the y axis label (default: from the declarations)", default=None)
    xlabel: str | None = doc("the x axis label (default: from the declarations)", default=None,
                             kinds=LINE_KINDS)
    runs: list[str] | None = doc("the ``[[runs]]`` drawn (default: all)", default=None)
    reference: list[str] | None = doc(
        "the y columns that are references (drawn as their continuous curve, solid black; "
        "the others are measured, solid in colour), beside those the runs' scenarios declare "
        "in ``[summary]`` (``reference_speed``, ``reference_accel``)", default=None,
        kinds=LINE_KINDS)
    error: str | None = doc(
        "a recorded error column (e.g. ``controller.speed_error``) drawn, times ``y_scale``, "
        "in a panel under each tracking axes; or ``\"reference\"``: each run's reference as "
        "drawn (its continuous curve) minus its measured series", default=None,
        kinds=LINE_KINDS)
    y_reduce: str | None = doc("``mean``: the mean of the columns y matches", default=None,
                               kinds=LINE_KINDS)
    y_minus: str | None = doc("a column: y - this column is drawn (an error)", default=None,
                              kinds=LINE_KINDS)
    limit_ref: str | None = doc(
        "with ``y_minus``: the zero-error reference speed column whose allowance (the "
        "``limit_*`` keys) is drawn", default=None, kinds=LINE_KINDS)
    ref: str | None = doc("the reference speed column the classes are of (speed classes: "
                          "required)", default=None, kinds=("speed_classes",))
    classes: list[float] | None = doc(
        "increasing class edges of the reference speed (km/h): [0, 30, 50] is (0, 30], "
        "(30, 50] (speed classes: required)", default=None, kinds=("speed_classes",))
    limit_kmh: float | None = doc(
        "the allowance at or below ``limit_below_kmh`` (km/h, >= 0; speed classes: "
        "required)", default=None)
    limit_below_kmh: float | None = doc(
        "the reference speed up to which ``limit_kmh`` holds (km/h, >= 0; speed classes: "
        "required)", default=None)
    limit_fraction: float | None = doc(
        "the allowance above it, a fraction of the reference speed (>= 0; speed classes: "
        "required)", default=None)
    xlim: list[float] | None = doc("[low, high]: the x range drawn, in the drawn unit (a "
                                   "zoom)", default=None, kinds=LINE_KINDS)
    ylim: list[float] | None = doc("[low, high]: the y range drawn, in the drawn unit",
                                   default=None, kinds=LINE_KINDS)
    band_x: list[float | str] | None = doc(
        "[low, high] or [low, high, label]: a shaded x band (e.g. the stop window)",
        default=None, kinds=LINE_KINDS)
    paper: str | None = doc("what the paper reports, shown under the figure",
                            default=None, kinds=("speed_classes",))

    def spec(self) -> dict[str, Any]:
        """The figure as the drawing functions of :mod:`cosim.run.figures` read it: TOML key
        -> value of every key given (an absent key is None here and left out there)."""
        return {key: getattr(self, f.name) for key, f in keys_of(Figure)
                if getattr(self, f.name) is not None}

    def line_kind(self) -> bool:
        """Whether it draws lines over x (``overlay`` or ``panels``)."""
        return self.kind in LINE_KINDS


@dataclass(frozen=True, kw_only=True)
class Variant:
    """``[[variants]]``: every claim again with some runs replaced (an alternative reading, a
    mechanism removed): a verdict per claim and variant in ``claims.md``, ``variants.csv``."""

    name: str = doc("the variant's name (a column of ``claims.md``): unique, not \"main\"")
    replace: dict[str, str] = doc(
        "``[[runs]]`` name -> the ``[[runs]]`` name replacing it in every claim (not empty)")
    text: str = doc("what the variant is (an alternative reading, a mechanism removed)",
                    default="")
    rounding: bool = doc("the perturbed floating-point rerun too, as the main claims get it",
                         default=True)
    seeds: int | None = doc("the first this many report seeds (>= 1, at most ``--seeds``; "
                            "default: ``--seeds``)", default=None)


@dataclass(frozen=True, kw_only=True)
class Statement:
    """``[[statements]]``: an assertion of the paper (a result or a conclusion) with the claims
    that test it, or why it cannot be tested: the page's statements table."""

    text: str = doc("the paper's assertion, in its words")
    where: str | None = doc("where the paper makes it (default: the sources of its claims)",
                            default=None)
    claims: list[str] | None = doc("the ids of the ``[[claims]]`` that test it (this or "
                                   "``untestable``)", default=None)
    untestable: str | None = doc("why it cannot be tested here (this or ``claims``)",
                                 default=None)
    headline: bool = doc("the result the paper is about (its title's method against its "
                         "rivals or its requirement): the page leads with whether it is "
                         "reproduced; needs ``claims``", default=False)

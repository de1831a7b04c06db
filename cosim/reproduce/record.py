"""What a reproduction's simulations produced, kept apart from what is made of it.

A :class:`Record` holds, for one entry, every simulation job it ran with that job's complete
specification (scenario, overrides, environment) and result (the run's ``summary.json``
content), and the recorded series its figures draw. The tables, claims, figures and page are
a function of the record and the entry (:mod:`cosim.reproduce`), so they are redrawn from
it in seconds without simulating; :func:`check_jobs` refuses a record that lacks a job the
entry needs or ran it with another specification.

On disk (``<folder>/record/``, gzip without timestamps so the same record gives the same
bytes): ``record.json.gz`` (the entry name, the digest of the simulation inputs
(:func:`cosim.run.provenance.simulation_digest`), K, the rounding flag, the build and the
jobs) and one
``series/<key>.csv.gz`` per recorded series, written with :data:`SERIES_DIGITS` significant
digits (a figure's resolution, a fifth of the bytes of full precision; the record is what
every drawing reads, so a run's first figures and any redraw are the same). The summaries,
which every number in the tables and claims comes from, are kept exactly.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

RECORD_DIR = "record"
_JOBS_FILE = "record.json.gz"
_SERIES_DIR = "series"
FORMAT = 1
SERIES_DIGITS = 7

# What the reproduction passes between its modules, as the runner gives it:
Summary = dict[str, Any]  # a run's summary (its summary.json): metric key -> value, tables nested
Overrides = dict[str, Any]  # a job's scenario overrides: "FMU.PARAMETER" -> value
MemberKey = tuple[str, str, int, int]  # a claim's member: run, ensemble, index, fp path


class RecordError(ValueError):
    """A record that cannot serve an entry (the message says which job or file, and why)."""


@dataclass(frozen=True)
class Job:
    """One simulation: ``kind`` (``run``: a table run's repetition; ``member``: a claim's
    ensemble member; ``sweep``: a sweep), its ``key`` (run name and repetition; run, ensemble,
    member index and floating-point path, 0 the main one; sweep name), and what fixes its
    result: the ``scenario``,
    the ``overrides`` and the environment ``env`` of the process that ran it."""

    kind: str
    key: tuple[Any, ...]
    scenario: str | list[str]
    overrides: Overrides
    env: dict[str, str] = field(default_factory=dict)

    def spec(self) -> dict[str, Any]:
        return {"kind": self.kind, "key": list(self.key), "scenario": self.scenario,
                "overrides": self.overrides, "env": self.env}


@dataclass
class Record:
    """The simulations of one entry: ``results`` maps each job's (kind, key) to its summary
    (a ``sweep``: the list of its rows; a failed member: None); ``series`` maps a series name
    (:func:`series_name`) to its recorded columns."""

    entry: str
    simulation: str  # digest of the simulation inputs the jobs ran with
    seeds: int  # K of the claims' members
    rounding: bool  # the claims' members ran on the perturbed floating-point path too
    build: str = "python"  # which builds of the catalog FMUs ran (cosim.reproduce.builds.BUILDS)
    jobs: dict[tuple[Any, ...], Job] = field(default_factory=dict)
    results: dict[tuple[Any, ...], Any] = field(default_factory=dict)
    series: dict[str, pd.DataFrame] = field(default_factory=dict)

    def add(self, job: Job, result: Any) -> None:
        ident = (job.kind, *job.key)
        self.jobs[ident] = job
        self.results[ident] = result

    def result(self, kind: str, *key: Any) -> Any:
        return self.results[(kind, *key)]

    def frame(self, name: str) -> pd.DataFrame:
        try:
            return self.series[name]
        except KeyError:
            raise RecordError(f"record of {self.entry}: no recorded series {name!r} (rerun "
                              f"`cosim reproduce {self.entry}`)") from None


def read_csv(path: Path, **kwargs: Any) -> pd.DataFrame:
    """``pandas.read_csv`` that reads back every float bit for bit (pandas 3 does by default;
    earlier versions need the round-trip parser)."""
    if int(pd.__version__.split(".")[0]) < 3:
        kwargs["float_precision"] = "round_trip"
    return pd.read_csv(path, **kwargs)


def series_name(kind: str, *key: Any) -> str:
    """The name of a recorded series: ``run/<run>`` or ``member/<run>/<i>``."""
    return "/".join([kind, *(str(k) for k in key)])


def _file_of(name: str) -> str:
    stem = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
    return f"{stem}_{hashlib.sha256(name.encode()).hexdigest()[:8]}.csv.gz"


def _gzip(data: bytes) -> bytes:
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb", mtime=0, filename="", compresslevel=6) as f:
        f.write(data)
    return buf.getvalue()


def save(record: Record, folder: Path) -> Path:
    """Write ``record`` to ``folder/record/`` (replacing what was there); returns that
    folder.

    The new record is written whole beside the old one, then the two folders are swapped by
    renames, so a kill at any point leaves one complete record: the old one until the swap,
    the new one after it (:func:`_settle`, which every reader calls, finishes a swap that was
    cut between its two renames)."""
    target, staging, old = _settle(folder)
    shutil.rmtree(staging, ignore_errors=True)
    (staging / _SERIES_DIR).mkdir(parents=True)
    files = {}
    for name, frame in sorted(record.series.items()):
        files[name] = _file_of(name)
        text = frame.to_csv(index=False, float_format=f"%.{SERIES_DIGITS}g",
                            lineterminator="\n")
        (staging / _SERIES_DIR / files[name]).write_bytes(_gzip(text.encode()))
    body = {"format": FORMAT, "entry": record.entry, "simulation": record.simulation,
            "seeds": record.seeds, "rounding": record.rounding, "build": record.build,
            "series": files,
            "jobs": [{**job.spec(), "result": record.results[ident]}  # in a fixed order,
                     for ident, job in sorted(record.jobs.items(),  # not the runs' finishing
                                              key=lambda item: json.dumps(item[0]))]}
    (staging / _JOBS_FILE).write_bytes(_gzip(json.dumps(body, sort_keys=True).encode()))
    if target.exists():
        target.replace(old)  # from here until the next rename, ``staging`` is complete
    staging.replace(target)
    shutil.rmtree(old, ignore_errors=True)
    return target


def _settle(folder: Path) -> tuple[Path, Path, Path]:
    """The record's folder, its staging folder and the replaced record's folder, after
    finishing a :func:`save` that was stopped between its two renames: with no record but a
    replaced one, the staging folder is complete if it has its jobs file (it is written
    before the first rename) and becomes the record, else the replaced record comes back;
    a replaced record left beside a record is removed."""
    target = folder / RECORD_DIR
    staging = folder / f".{RECORD_DIR}.tmp"
    old = folder / f".{RECORD_DIR}.old"
    if old.exists():
        if not target.exists():
            (staging if (staging / _JOBS_FILE).exists() else old).replace(target)
        shutil.rmtree(old, ignore_errors=True)
    return target, staging, old


def _body(path: Path) -> dict[str, Any]:
    try:
        return json.loads(gzip.decompress(path.read_bytes()))
    except FileNotFoundError:
        raise RecordError(f"{path}: no record (run `cosim reproduce` first)") from None
    except (OSError, ValueError) as err:
        raise RecordError(f"{path}: unreadable record ({err})") from None


def simulation_of(folder: Path) -> tuple[str, int]:
    """(simulation digest, K of the claims' members) of the record in ``folder/record/``."""
    body = _body(_settle(folder)[0] / _JOBS_FILE)
    return str(body.get("simulation")), int(body.get("seeds", 0))


def build_of(folder: Path) -> str:
    """The build (``cosim reproduce --build``) of the record in ``folder/record/``; "python"
    where there is no record."""
    try:
        return str(_body(_settle(folder)[0] / _JOBS_FILE).get("build", "python"))
    except RecordError:
        return "python"


def load(folder: Path) -> Record:
    """The record in ``folder/record/`` (:class:`RecordError` naming the file if there is
    none or it cannot be read)."""
    path = _settle(folder)[0] / _JOBS_FILE
    body = _body(path)
    if body.get("format") != FORMAT:
        raise RecordError(f"{path}: record format {body.get('format')!r}, this version reads "
                          f"{FORMAT} (rerun `cosim reproduce {body.get('entry', '')}`)")
    rec = Record(body["entry"], body["simulation"], int(body["seeds"]), bool(body["rounding"]),
                 str(body.get("build", "python")))
    for item in body["jobs"]:
        key = tuple(item["key"])
        if item["kind"] == "member" and isinstance(key[3], bool):  # a record of one rerun:
            key = (*key[:3], int(key[3]))  # its flag is path 0 (main) or 1 (the rerun)
        scenario = item["scenario"]
        rec.add(Job(item["kind"], key, scenario if isinstance(scenario, str) else
                    list(scenario), item["overrides"], item["env"]), item["result"])
    for name, file in body["series"].items():
        rec.series[name] = read_csv(folder / RECORD_DIR / _SERIES_DIR / file)
    return rec


def known(record: Record | None, job: Job) -> bool:
    """Whether ``record`` holds ``job`` with the same specification (and a result)."""
    if record is None:
        return False
    have = record.jobs.get((job.kind, *job.key))
    return (have is not None and _same(have, job)
            and record.results[(job.kind, *job.key)] is not None)


def _same(a: Job, b: Job) -> bool:
    """Whether two jobs have the same specification (as the record stores it)."""
    return json.dumps(a.spec(), sort_keys=True) == json.dumps(b.spec(), sort_keys=True)


def check_jobs(record: Record, wanted: list[Job]) -> None:
    """:class:`RecordError` naming the first job of ``wanted`` the record does not have with
    the same specification."""
    for job in wanted:
        have = record.jobs.get((job.kind, *job.key))
        if have is None:
            raise RecordError(f"record of {record.entry}: no {job.kind} {list(job.key)} (the "
                              f"entry asks for more than was simulated; rerun `cosim reproduce "
                              f"{record.entry}`)")
        if not _same(have, job):
            raise RecordError(f"record of {record.entry}: {job.kind} {list(job.key)} ran as "
                              f"{have.spec()}, the entry now asks for {job.spec()} (rerun "
                              f"`cosim reproduce {record.entry}`)")

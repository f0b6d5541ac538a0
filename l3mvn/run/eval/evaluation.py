"""An evaluation run: the episodes still to do, run on a backend, each result line appended as it
finishes, and the summary of what was run.

``--out`` is locked for the whole run and its torn tail set aside first; with ``resume`` the lines
already there for the same policy and config count and are not run again. A row that fails
``row_problem`` is never summarised. A recording or video that does not reach the disk keeps its
result and is named at the end. Ctrl-C keeps every finished episode.
"""

from __future__ import annotations

from collections.abc import Generator
from contextlib import closing
from dataclasses import dataclass, field
from typing import TextIO

from tqdm import tqdm

from l3mvn.core.errors import L3MVNError, one_line
from l3mvn.run.eval import backends
from l3mvn.run.eval.job import EvalJob, is_error_row
from l3mvn.run.eval.results import ResultWriter, row_problem
from l3mvn.world.episode import Episode

BACKENDS = ("local", "ray")


@dataclass
class Evaluation:
    """What a run produced: the valid rows by episode key (resumed ones included), how many episodes
    failed to run, what did not reach the disk, and whether it was interrupted."""

    rows: dict[str, dict] = field(default_factory=dict)
    errors: int = 0
    unwritten: list[str] = field(default_factory=list)
    interrupted: bool = False


def evaluate(
    job: EvalJob,
    episodes: list[Episode],
    *,
    out: str | None = None,
    resume: bool = False,
    backend: str = "local",
    workers: int | None = None,
    address: str | None = None,
    video_dir: str | None = None,
    stream: TextIO | None = None,
) -> Evaluation:
    """Run ``episodes`` of ``job`` (those not already in ``out`` with ``resume``) and append each result
    line to ``out``; progress and per-episode problems go to ``stream`` (None: silent). ``video_dir``:
    an MP4 per episode there, from its recording."""
    if backend not in BACKENDS:
        raise L3MVNError(f"unknown backend {backend!r}; valid: {', '.join(BACKENDS)}")
    rule = job.config.task.success_rule
    run = Evaluation()
    wanted = {ep.key for ep in episodes}
    with ResultWriter(out) as writer:
        if writer.repair:
            _say(stream, writer.repair)
        if resume:
            previous = writer.previous(job.policy, job.config_hash, rule)
            if out is not None and (report := previous.report(out)):
                _say(stream, report)
            run.rows = {key: row for key, row in previous.rows.items() if key in wanted}
        todo = [ep.key for ep in episodes if ep.key not in run.rows]
        eset = job.load()
        _say(
            stream,
            f"{eset.name}/{eset.split} ({eset.format}): {len(episodes)} episodes, {len(todo)} to run, "
            f"policy {job.policy}, rule {rule}, config {job.config_hash}",
        )
        rows = _rows(job, todo, backend, workers, address)
        try:
            with (
                closing(rows),
                tqdm(
                    total=len(todo), unit="ep", file=stream, dynamic_ncols=True, mininterval=1.0, disable=stream is None
                ) as bar,
            ):
                for row in rows:
                    writer.write(row)
                    bar.update(1)
                    _take(run, row, rule, video_dir, job, bar)
        except KeyboardInterrupt:
            run.interrupted = True  # the episodes finished so far still get their summary
    return run


def _rows(
    job: EvalJob, todo: list[str], backend: str, workers: int | None, address: str | None
) -> Generator[dict, None, None]:
    if backend == "ray":
        from l3mvn.run.eval.ray_backend import run_ray

        return run_ray(job, todo, address, workers)
    return backends.run_local(job, todo, workers or 1)


def _take(run: Evaluation, row: dict, rule: str, video_dir: str | None, job: EvalJob, bar: tqdm) -> None:
    """Count one finished row: an error, a result, and whether its recording and video are whole."""
    problem = row["error"] if is_error_row(row) else row_problem(row, rule)
    if problem:
        run.errors += 1
        bar.write(f"{row.get('key')}: error: {problem}")
        return
    run.rows[row["key"]] = row
    if row.get("recording_error"):
        run.unwritten.append(row["recording_error"])
        bar.write(f"{row['key']}: error: {row['recording_error']}")
    elif video_dir and job.record_dir and (problem := _episode_video(row, job.record_dir, video_dir)):
        run.unwritten.append(problem)
        bar.write(f"{row['key']}: no video: {problem}")
    done = list(run.rows.values())
    bar.set_postfix_str(
        f"SR {sum(r['success'] for r in done) / len(done):.3f} SPL {sum(r['spl'] or 0 for r in done) / len(done):.3f}"
    )


def _episode_video(row: dict, record_dir: str, video_dir: str) -> str | None:
    """The finished episode's recording as an MP4 (a local run's recordings only); why it could not
    be written, or None."""
    from l3mvn.run.eval.result_videos import export_result_video

    try:
        export_result_video(row, record_dir, video_dir)
    except L3MVNError as exc:
        return one_line(exc)
    return None


def _say(stream: TextIO | None, text: str) -> None:
    if stream is not None:
        print(text, file=stream)

"""A training run's folder, the same for every agent: checkpoint.pkl (atomic), config.json,
log CSVs cut back to a checkpoint on resume, summary.json, and the software each part of a
resumed run was trained with."""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import pickle
import warnings
from pathlib import Path

import jax

from stori_jax.checks import check_int
from stori_jax.provenance import software

# how far an evaluated checkpoint's run had trained, as an evaluation records it
TRAINING_KEYS = ("trained_agent_steps", "run_total_steps", "run_finished")


def save_checkpoint(path: Path, payload: dict) -> None:
    """Atomically write ``payload`` (params, optimizer state, keys, env snapshots, ...)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as f:
        pickle.dump(jax.device_get(payload), f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)


def read_checkpoint(path: Path, what: str = "stori-jax") -> dict:
    """The unpickled payload of a checkpoint file (a dict with a ``format``).

    Raises:
        ValueError: no such file, or it is not a checkpoint (``what`` names the kind in the
            message)."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"checkpoint {path} does not exist")

    def refuse(why: str):
        return ValueError(f"not a {what} checkpoint: {path} ({why})")

    if not path.is_file():
        raise refuse("a directory; give the checkpoint.pkl in it" if path.is_dir()
                     else "not a regular file")
    try:
        with open(path, "rb") as f:
            payload = pickle.load(f)
    except Exception as e:  # unpickling junk can raise almost anything
        raise refuse(f"unreadable: {type(e).__name__}: {e}") from None
    if not isinstance(payload, dict) or not isinstance(payload.get("format"), str):
        raise refuse("no format marker")
    return payload


class RunConfig:
    """What an agent's frozen config dataclass shares: reading it back from a run, and
    ``--set FIELD=VALUE`` overrides typed by the field.  ``TITLE`` names the agent in errors."""

    TITLE = "agent"

    @classmethod
    def from_recorded(cls, recorded: dict):
        """The config a run recorded (config.json, a checkpoint).  A field added since the run
        was recorded takes its default, which is what the run was trained with."""
        unknown = sorted(set(recorded) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise ValueError(f"recorded {cls.TITLE} config has unknown fields {unknown}")
        return cls(**recorded)

    @classmethod
    def from_overrides(cls, base, overrides: dict[str, str]):
        """``base`` with ``field=value`` strings from the command line, typed by the field."""
        fields = {f.name for f in dataclasses.fields(cls)}
        typed = {}
        for name, text in overrides.items():
            if name not in fields:
                raise ValueError(f"unknown {cls.TITLE} hyperparameter {name!r}; known: "
                                 f"{sorted(fields)}")
            kind = type(getattr(base, name))
            if kind is bool:
                if text.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(f"{name} must be true or false, got {text!r}")
                typed[name] = text.lower() in ("true", "1")
            else:
                try:
                    typed[name] = kind(text)
                except ValueError:
                    kind_name = {int: "an int", float: "a number"}.get(kind, kind.__name__)
                    raise ValueError(f"{name} must be {kind_name}, got {text!r}") from None
        return dataclasses.replace(base, **typed)


def check_checkpoint(payload: dict, path: Path, *, checkpoint_format: str, config_class) -> dict:
    """``payload`` (read from ``path``) if it is a checkpoint of ``checkpoint_format`` with a
    config ``config_class`` reads; a ValueError saying why not."""
    def refuse(why: str):
        return ValueError(f"not a stori-jax {config_class.TITLE} checkpoint: {path} ({why})")

    if payload["format"] != checkpoint_format:
        raise refuse(f"no format {checkpoint_format!r} marker")
    missing = [k for k in ("config", "params") if k not in payload]
    if missing:
        raise refuse(f"lacks {missing}")
    if not isinstance(payload["config"], dict):
        raise refuse("its config is not a dict")
    try:
        config_class.from_recorded(payload["config"])
    except (ValueError, TypeError) as e:
        raise refuse(f"bad config: {e}") from None
    return payload


def resumable(ckpt: dict, config, path: Path, resume_state, stop_after: int | None) -> dict:
    """``ckpt`` if a run of ``config`` can continue from it: trained under ``config``, holding
    every key of ``resume_state``, and not beyond ``stop_after`` iterations."""
    recorded = dataclasses.asdict(type(config).from_recorded(ckpt["config"]))
    differ = [f"{k} {recorded[k]!r} there, {v!r} now"
              for k, v in dataclasses.asdict(config).items() if recorded[k] != v]
    if differ:
        raise ValueError(f"cannot resume from {path}: it was trained with a different "
                         "config: " + "; ".join(differ))
    missing = [k for k in resume_state if k not in ckpt]
    if missing:
        raise ValueError(f"cannot resume from {path}: it lacks {missing}, which a run "
                         "needs to continue")
    if stop_after is not None and stop_after < ckpt["iteration"]:
        raise ValueError(f"stop_after {stop_after} is before {path}'s iteration "
                         f"{ckpt['iteration']}: a run cannot go back")
    return ckpt


@dataclasses.dataclass(frozen=True)
class TrainStart:
    """Where one ``train`` call starts (:func:`start_training`): the run folder ``out``, the
    iteration it stops after (``last``), the checkpoint it resumes (``ckpt``; None: a fresh
    run) and the software it starts with (``made_with``)."""

    out: Path
    last: int
    ckpt: dict | None
    made_with: dict
    log_fields: tuple
    episode_fields: tuple

    @property
    def checkpoint(self) -> Path:
        return self.out / "checkpoint.pkl"

    @property
    def log(self) -> Path:
        return self.out / "log.csv"

    @property
    def episodes(self) -> Path:
        return self.out / "episodes.csv"

    @property
    def nothing_to_train(self) -> bool:
        """A resume whose checkpoint has trained as far as this call would."""
        return self.ckpt is not None and self.ckpt["iteration"] == self.last

    def untrained(self, summary: dict) -> dict:
        """The result of a call with nothing to train: ``summary`` (the run's, as recorded),
        written to summary.json only if an interruption came before it; no other file."""
        if not (self.out / "summary.json").exists():
            write_summary(self.out, summary)
        return dict(summary, iterations_now=0, agent_steps_now=0)

    def begin_files(self, config) -> list:
        """A fresh run's config.json and empty logs; its software parts."""
        (self.out / "config.json").write_text(json.dumps(dataclasses.asdict(config), indent=1))
        rewrite_csv(self.log, self.log_fields, [])
        rewrite_csv(self.episodes, self.episode_fields, [])
        return [dict(from_iteration=0, software=self.made_with)]

    def resume_files(self, upto_step: int) -> list:
        """A resumed run's logs cut back to its checkpoint (``upto_step``); its software parts,
        this call's appended where it differs (:func:`software_parts`)."""
        parts = software_parts(self.ckpt, self.ckpt["iteration"], self.made_with,
                               self.checkpoint)
        for path, fields in ((self.log, self.log_fields), (self.episodes, self.episode_fields)):
            rewrite_csv(path, fields, rows_upto(path, fields, upto_step))
        return parts


def start_training(config, out: Path, agent: str, *, resume: bool, stop_after: int | None,
                   load_checkpoint, resume_state, log_fields, episode_fields) -> TrainStart:
    """The train / resume preamble of every agent: the software this call starts with (before
    training, not whatever is installed when it ends), ``stop_after`` checked, ``out`` made,
    a fresh run refused over another (:func:`check_no_run_here`), and on ``resume`` the
    checkpoint ``load_checkpoint`` reads, checked :func:`resumable`."""
    made_with = software()
    if stop_after is not None:
        check_int("stop_after", stop_after, 1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    last = config.num_iterations if stop_after is None else min(stop_after,
                                                                config.num_iterations)
    if not resume:
        check_no_run_here(out, agent)
    path = out / "checkpoint.pkl"
    ckpt = resumable(load_checkpoint(path), config, path, resume_state,
                     stop_after) if resume else None
    return TrainStart(out=out, last=last, ckpt=ckpt, made_with=made_with,
                      log_fields=tuple(log_fields), episode_fields=tuple(episode_fields))


def rewrite_csv(path: Path, fields, rows) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(fields)
        writer.writerows(rows)


def append_csv(path: Path, rows) -> None:
    with open(path, "a", newline="") as f:
        csv.writer(f).writerows(rows)


def rows_upto(path: Path, fields, upto_step: int) -> list[list[str]]:
    """The rows of a log CSV whose global_step is <= ``upto_step``."""
    column = fields.index("global_step")
    with open(path, newline="") as f:
        rows = list(csv.reader(f))[1:]
    return [r for r in rows if int(r[column]) <= upto_step]


def recorded_parts(ckpt: dict) -> list:
    """The checkpoint's software history (unrecorded software, None, in one from before it was
    kept)."""
    return list(ckpt.get("software_parts", [dict(from_iteration=0, software=None)]))


def software_parts(ckpt: dict, start: int, made_with: dict, path: Path) -> list:
    """The checkpoint's software history, with this part's software appended where it differs
    from the last part's (a warning says so). A checkpoint written before the history was kept
    starts it with unrecorded software (None)."""
    parts = recorded_parts(ckpt)
    before = parts[-1]["software"]
    if before == made_with:
        return parts
    if before is not None:
        changed = [f"{name} {before.get(name)!r} -> {made_with[name]!r}"
                   for name in ("python", "machine", "commit")
                   if before.get(name) != made_with[name]]
        changed += [f"{name} {version!r} -> {made_with['packages'][name]!r}"
                    for name, version in before.get("packages", {}).items()
                    if version != made_with["packages"].get(name)]
        warnings.warn(f"resuming from {path}: it was trained so far with other software "
                      f"({'; '.join(changed)}): from iteration {start} on, the run may not "
                      "match an uninterrupted one bit for bit", stacklevel=4)
    return parts + [dict(from_iteration=start, software=made_with)]


def check_no_run_here(out: Path, agent: str = "AGENT") -> None:
    """A fresh run is not trained over another: one with a checkpoint (resume it instead), or
    a finished one whose checkpoint is gone (:func:`check_no_finished_run`).  A run stopped
    before its first checkpoint (no summary yet) is simply started again."""
    if (Path(out) / "checkpoint.pkl").exists():
        raise ValueError(f"{out} already holds a run: resume it (stori-jax train {agent} ... "
                         "--resume), or train into another directory (--out DIR)")
    check_no_finished_run(out, elsewhere=f"stori-jax train {agent} ... --out DIR")


def check_no_finished_run(out: Path, prefix: str = "",
                          elsewhere: str = "stori-jax train AGENT ... --out DIR") -> None:
    """Refuse ``out`` if it holds a finished run (its summary or an evaluation) whose
    checkpoint is gone (checkpoints are not committed): it cannot be continued, and a fresh
    run there would start again over its files and leave the old evaluations beside it.
    ``prefix`` and ``elsewhere`` (how to train into another directory) word it for a caller."""
    out = Path(out)
    finished = [path.name for path in [out / "summary.json", *sorted(out.glob("eval-*.json"))]
                if path.exists()]
    if finished and not (out / "checkpoint.pkl").exists():
        raise ValueError(f"{prefix}{out} holds a finished run ({', '.join(finished)}) without "
                         "its checkpoint.pkl (checkpoints are not committed): it cannot be "
                         "continued, and a new run there would leave its evaluations beside "
                         f"yours; train into another directory ({elsewhere})")


def write_summary(out: Path, summary: dict) -> None:
    """``out``/summary.json, once the run has finished (its table and evaluation read it)."""
    if summary["finished"]:
        (Path(out) / "summary.json").write_text(json.dumps(summary, indent=1))


# the cores a process's emulator workers may use, where fewer than its CPU affinity allows
CORES_VARIABLE = "STORI_JAX_CORES"


def cores() -> int:
    """The cores this process's emulator workers may use: as many as its CPU affinity allows,
    or fewer where the environment variable ``STORI_JAX_CORES`` says so.  ``stori-jax grid``
    sets it in each trial to the CPUs Ray reserved for it: Ray counts CPUs but pins no process
    to them, so a trial would otherwise start workers for every core of its node, in every
    trial at once.  The split of envs over workers never changes the results."""
    allowed = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
        os.cpu_count() or 1)
    capped = os.environ.get(CORES_VARIABLE)
    if not capped:
        return allowed
    try:
        budget = int(capped)
    except ValueError:
        raise ValueError(f"{CORES_VARIABLE} must be a whole number of cores, "
                         f"got {capped!r}") from None
    if budget < 1:
        raise ValueError(f"{CORES_VARIABLE} must be >= 1, got {budget}")
    return min(allowed, budget)


def workers_within_cores(num_envs: int) -> dict:
    """``stori_jax.make``'s ``num_workers`` and ``inline_envs`` for a batch of ``num_envs``
    under :func:`cores`: {} (make's own default, from the CPU affinity) unless
    ``STORI_JAX_CORES`` caps the cores, and then make's default rule on that many."""
    if not os.environ.get(CORES_VARIABLE):
        return {}
    from stori_jax.builder import default_split

    workers, inline = default_split(num_envs, cores())
    return dict(num_workers=workers, inline_envs=inline)

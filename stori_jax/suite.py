"""``stori-jax suite``: every paper preset (or a subset) for N episodes with an agent (the
uniformly random policy, or a trained checkpoint's), a results table (markdown + JSON) and a
gallery of contact sheets."""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import shutil
import socket
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from stori_jax.folders import removed_if_left_empty
from stori_jax.provenance import software


def random_policy(num_actions: int):
    """policy(obs, key) -> (B,) uniformly random actions."""
    import jax
    import jax.numpy as jnp

    return jax.jit(lambda obs, key: jax.random.randint(key, (obs.shape[0],), 0, num_actions,
                                                       jnp.int32))


def episode_quotas(episodes: int, num_envs: int) -> np.ndarray:
    """How many episodes each env plays: ``episodes`` split as evenly as possible (fixed
    quotas, so that a sample of episodes does not favour the short ones)."""
    return np.array([episodes // num_envs + (i < episodes % num_envs) for i in range(num_envs)])


def play(env, obs, seed: int, *, max_steps: int, episodes: int | None = None,
         progress: str | None = None, policy=None) -> dict:
    """Step ``env`` from ``obs`` (its reset's) under ``policy(obs, key)`` (default: uniformly
    random), keys from ``seed``'s agent stream (:func:`stori_jax.agent_key`), for
    ``max_steps`` agent steps or until every env played its quota of ``episodes``
    (:func:`episode_quotas`; None: no quota); count what happened.  The
    returns are those of the episodes within the quotas (all of them without ``episodes``);
    events, corruptions and masks are counted over every step played.  The first step is not
    timed (it compiles the env's step and the policy): ``env_steps_per_s`` is that of the steps
    after it (None after one step)."""
    import jax
    from tqdm import tqdm

    from stori_jax.core import agent_key

    policy = policy or random_policy(env.num_actions)
    key = agent_key(seed)
    quotas = (np.full(env.num_envs, np.iinfo(np.int64).max) if episodes is None
              else episode_quotas(episodes, env.num_envs))
    ended = np.zeros(env.num_envs, np.int64)
    returns, events, corrupted, slots, masked, switches, steps = [], 0, 0, 0, 0, 0, 0
    previous_concept = np.zeros(env.num_envs, np.int32)
    bar = tqdm(total=max_steps, desc=progress, unit="step", disable=progress is None,
               leave=episodes is None)
    start = None
    while steps < max_steps and (ended < quotas).any():
        key, k = jax.random.split(key)
        obs, _, terminated, truncated, info = env.step(policy(obs, k))
        done = np.asarray(terminated | truncated)
        counted = done & (ended < quotas)
        returns.extend(np.asarray(info["episode_return"])[counted].tolist())
        ended += done
        events += int(np.asarray(info["event_fired"]).sum())
        # draws of the slots played only: not an env reset instead, nor (at frame granularity)
        # the frames after an episode's last one
        flags = np.asarray(info["action_corrupted"]).reshape(env.num_envs, -1)
        played = np.arange(flags.shape[1]) < np.asarray(info["frames_played"])[:, None]
        corrupted += int(flags[played].sum())
        slots += int(played.sum())
        masked += int(np.asarray(info["obs_masked"]).sum())
        concept = np.asarray(info["concept"])
        switches += int((concept != previous_concept).sum())
        previous_concept = np.where(done, 0, concept)
        steps += 1
        bar.update()
        if start is None:  # after the first step: it compiled
            start = time.perf_counter()
    bar.close()
    elapsed = time.perf_counter() - start if start is not None else 0.0
    timed = max(steps - 1, 0)
    return dict(episodes=len(returns), mean_return=float(np.mean(returns)) if returns else None,
                events_fired=events, corrupted_actions=corrupted, action_draws=slots,
                corrupted_fraction=corrupted / max(slots, 1), masked_obs=masked,
                masked_fraction=masked / max(steps * env.num_envs, 1), concept_switches=switches,
                agent_steps=steps, timed_agent_steps=timed,
                env_steps_per_s=timed * env.num_envs / elapsed if timed and elapsed > 0 else None,
                elapsed_s=elapsed)


def run_preset(game: str, name: str, *, episodes: int, num_envs: int, max_steps: int,
               seed: int, policy=None, progress: bool = False) -> dict:
    """Play until every env played its quota of ``episodes`` (or ``max_steps`` agent steps)."""
    import stori_jax

    with stori_jax.make(game, name, num_envs=num_envs, seed=seed, obs="atari84") as env:
        obs, _ = env.reset()
        stats = play(env, obs, seed, max_steps=max_steps, episodes=episodes, policy=policy,
                     progress=f"{game} {name}" if progress else None)
    return dict(game=game, preset=name, definition=stori_jax.describe_preset(game, name),
                **stats)


def table(rows: list[dict]) -> str:
    lines = ["| game | preset | definition | mean return | episodes | events fired | "
             "corrupted actions (of draws) | masked obs | env steps/s (after the first) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        mean = "-" if r["mean_return"] is None else f"{r['mean_return']:.1f}"
        lines.append(f"| {r['game']} | {r['preset']} | {r['definition']} | {mean} | "
                     f"{r['episodes']} | {r['events_fired']} | "
                     f"{r['corrupted_actions']} ({r['corrupted_fraction']:.0%}) | "
                     f"{r['masked_fraction']:.0%} | {_rate(r['env_steps_per_s'])} |")
    return "\n".join(lines) + "\n"


def _rate(steps_per_s: float | None) -> str:
    return "-" if steps_per_s is None else f"{steps_per_s:.0f}"


def short_rows_note(rows: list[dict], episodes: int, num_envs: int, max_steps: int) -> str:
    """A line under the table where a row has fewer episodes than asked: --max-steps came
    first (each env plays a fixed share of the episodes, so another env's finished episodes do
    not stand in)."""
    short = [f"{r['game']} {r['preset']}" for r in rows if r["episodes"] < episodes]
    if not short:
        return ""
    shares = ", ".join(map(str, episode_quotas(episodes, num_envs)))
    return (f"\nFewer than {episodes} episode{'s' * (episodes != 1)} in {', '.join(short)}: "
            f"each run stopped at --max-steps {max_steps} agent steps first. Each of the "
            f"{num_envs} envs plays a fixed share of the episodes ({shares}), so that short "
            "episodes are not favoured.\n")


STAGING_PREFIX = ".suite-partial-"  # then <pid>@<host>- of the run that stages its sheets


def _host() -> str:
    """This machine as a staging folder names it: a hash of its name (safe in a file name, and
    'node-1' is not 'node_1')."""
    return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:16]


def _run_id() -> str:
    """This process as a staging folder names it: its pid and its machine."""
    return f"{os.getpid()}@{_host()}"


def remove_abandoned_staging(out: Path) -> list[Path]:
    """Remove the staging folders in ``out`` of suite runs of this machine that are gone
    without cleaning up (killed by SIGTERM or SIGKILL, a closed terminal: only an exception or
    Ctrl-C removes its own).  A running suite's folder (its pid alive) stays, and so does
    another machine's (its pids mean nothing here), or one named otherwise."""
    removed, host = [], _host()
    for folder in sorted(Path(out).glob(f"{STAGING_PREFIX}*")):
        pid, _, machine = folder.name[len(STAGING_PREFIX):].rpartition("-")[0].partition("@")
        if folder.is_dir() and pid.isdigit() and machine == host and not _alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, OverflowError):  # no such process; no such pid number
        return False
    except PermissionError:  # another user's process: alive
        pass
    return True


def sheet_path(out: Path, game: str, name: str) -> Path:
    """Where a suite run in ``out`` puts the contact sheet of ``game``'s preset ``name``."""
    return out / "gallery" / f"{game}-{name}.png"


def suite_outputs(out: Path) -> list[Path]:
    """Every file a suite run can write in ``out``: its table, its JSON and each paper preset's
    contact sheet."""
    from stori_jax import list_presets

    return [out / "table.md", out / "results.json"] + [
        sheet_path(out, game, name) for game, name in list_presets()]


def remove_stale_outputs(out: Path, written: list[Path]) -> list[Path]:
    """After a run has written ``written`` in ``out``: remove the files an earlier suite run
    left there that this one did not replace (nothing else), so that a run on a subset of the
    presets leaves no contact sheet beside a table that no longer lists it."""
    stale = [path for path in suite_outputs(out) if path not in written and path.is_file()]
    for path in stale:
        path.unlink()
    return stale


def default_out() -> Path:
    """Where a suite run writes without --out: results/suite-<today>."""
    return Path("results") / f"suite-{datetime.date.today().isoformat()}"


def run_suite(presets, *, episodes: int, num_envs: int, max_steps: int, seed: int,
              out: Path | None, gallery: bool, progress: bool = True,
              trained=None, checkpoint: Path | None = None) -> Path:
    """Run ``presets`` [(game, name)] with the random policy, or a ``trained``
    :class:`stori_jax.plugins.TrainedPolicy` (loaded from ``checkpoint`` when only that is
    given), which plays its own game only: every preset must be of that game, and ``seed``
    must not be one of its training envs' seeds.  The gallery's contact sheets show what each
    preset perturbs, under random play either way."""
    from tqdm import tqdm

    import stori_jax
    from stori_jax.visual import contact_sheet

    made_with = software()  # when the run starts
    out = Path(out) if out else default_out()
    policy = agent = None
    if trained is None and checkpoint is not None:
        from stori_jax.plugins import trained_policy

        trained = trained_policy(checkpoint)
    if trained is not None:
        policy = trained.act
        others = sorted({g for g, _ in presets if g != trained.game})
        if others:
            raise ValueError(f"--checkpoint {checkpoint} plays {trained.game} only; choose its "
                             f"presets with --games {trained.game} (asked for {others})")
        if seed in trained.train_env_seeds:
            raise ValueError(f"eval seed {seed} is one of the training envs' seeds "
                             f"{list(trained.train_env_seeds)} (training seed {trained.seed}): "
                             "the evaluation would replay training's episodes; choose another "
                             f"--seed (by default the training seed + "
                             f"{trained.eval_seed - trained.seed})")
        agent = str(checkpoint) if checkpoint is not None else trained.agent
    rows, written = [], [out / "results.json", out / "table.md"]
    # the sheets wait in a hidden folder until the run has finished: an interrupted run leaves
    # the earlier run's gallery, table and JSON as they were, not a mix of two runs (and an
    # interrupted first run no empty folder)
    with removed_if_left_empty(out):
        out.mkdir(parents=True, exist_ok=True)
        remove_abandoned_staging(out)
        staging = Path(tempfile.mkdtemp(dir=out, prefix=f"{STAGING_PREFIX}{_run_id()}-"))
        try:
            for game, name in tqdm(presets, desc="suite", unit="preset", disable=not progress):
                rows.append(run_preset(game, name, episodes=episodes, num_envs=num_envs,
                                       max_steps=max_steps, seed=seed, policy=policy,
                                       progress=progress))
                if gallery:
                    contact_sheet(game, name, stori_jax.preset(game, name),
                                  sheet_path(staging, game, name), seed=seed)
            for game, name in presets if gallery else ():
                written.append(sheet_path(out, game, name))
                written[-1].parent.mkdir(exist_ok=True)
                os.replace(sheet_path(staging, game, name), written[-1])
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    (out / "results.json").write_text(json.dumps(dict(
        agent=agent or "random", seed=seed, episodes=episodes, num_envs=num_envs,
        max_steps=max_steps, software=made_with, rows=rows),
        indent=1))
    text = (f"Agent: {agent or 'uniformly random policy'}\n\n" + table(rows)
            + short_rows_note(rows, episodes, num_envs, max_steps))
    if gallery:
        text += "\nGallery (random play, 3.1 twin beside each preset): " + ", ".join(
            f"[{g} {n}]({sheet_path(out, g, n).relative_to(out)})" for g, n in presets) + "\n"
    (out / "table.md").write_text(text)
    stale = remove_stale_outputs(out, written)
    if stale:
        print(f"removed {len(stale)} contact sheets of an earlier suite run in {out} that this "
              "run did not make", file=sys.stderr)
    return out

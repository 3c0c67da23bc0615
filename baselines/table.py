"""``stori-jax table RESULTS_DIR``: every evaluation under RESULTS_DIR aggregated into the
paper's layout (game x preset, mean ± std over seeds) beside the paper's DreamerV3 and STORM
numbers, as markdown and JSON, and learning curves per game (PNG, one panel per preset, a row
of panels per agent).  The table has a column per trained agent of :mod:`baselines.agents`
that has evaluations here (in ``AGENT_MODULES``' order), then the random policy's, then the
paper's; each run's config is read by its agent's ``config_class``.

It reads ``eval-<policy>.json`` files (written by ``stori-jax eval``) and, for the curves, the
``episodes.csv`` of each training run (written by ``stori-jax train``), wherever they lie below
RESULTS_DIR.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from baselines.agents import RANDOM, agent_names, get_agent
from baselines.evaluate import CHECKPOINT_POLICIES, stori_game
from stori_jax.checks import MAX_SEED, check_int, check_real
from stori_jax.presets import canonical_preset

# docs/spec.md section 11: mean evaluation return ± std over seeds 0, 7, 13 at 100k agent steps
PAPER_RESULTS = {  # (game, preset): (DreamerV3 mean, std, STORM mean, std)
    ("Breakout", "1"): (8.67, 0.30, 9.20, 1.72),
    ("Breakout", "2.1"): (13.80, 3.26, 16.44, 2.03),
    ("Breakout", "2.2"): (14.86, 1.74, 20.45, 2.92),
    ("Breakout", "3.1"): (60.71, 41.89, 24.17, 3.55),
    ("Breakout", "3.2A"): (10.65, 0.41, 12.05, 0.89),
    ("Breakout", "3.2B"): (3.57, 1.43, 6.48, 2.50),
    ("Breakout", "3.2C"): (1.89, 0.49, 3.96, 1.42),
    ("Boxing", "1"): (39.32, 6.79, 29.48, 15.41),
    ("Boxing", "2.1"): (43.00, 31.98, 54.69, 20.44),
    ("Boxing", "2.2"): (42.21, 35.54, 22.44, 3.54),
    ("Boxing", "3.1"): (84.22, 1.68, 86.18, 11.29),
    ("Boxing", "3.2A"): (86.90, 1.33, 85.22, 11.77),
    ("Boxing", "3.2B"): (61.74, 17.71, 45.41, 26.56),
    ("Boxing", "3.2C"): (56.52, 18.45, 52.66, 25.68),
    ("Gopher", "1"): (1137.00, 56.98, 1303.53, 724.76),
    ("Gopher", "2.1"): (11333.53, 14761.12, 950.67, 188.37),
    ("Gopher", "2.2"): (2190.87, 407.24, 2315.40, 893.32),
    ("Gopher", "3.1"): (3235.27, 443.51, 3811.67, 2431.85),
    ("Gopher", "3.2"): (1521.13, 451.45, 936.40, 106.83),
    ("BankHeist", "1"): (197.63, 20.76, 128.03, 31.41),
    ("BankHeist", "2.1"): (663.60, 587.85, 467.80, 507.74),
    ("BankHeist", "2.2"): (682.67, 476.90, 267.70, 295.86),
    ("BankHeist", "3.1"): (562.30, 320.74, 1015.73, 148.43),
    ("BankHeist", "3.2"): (849.80, 514.15, 43.10, 22.85),
}
PAPER_AGENT_STEPS = 100_000  # the paper's training budget per run
# presets whose paper numbers came from the reference's environment with a defect that changes
# the game, which this project corrects (docs/spec.md marks the reference's defects)
PAPER_ENVIRONMENT_DIFFERS = {
    ("Gopher", "2.1"): "the reference's 'hole stays open' rule mostly undid the gopher's "
                       "digging (docs/spec.md section 7, the likely cause of DreamerV3's 11333); "
                       "here it undoes only the farmer's fills",
    ("BankHeist", "2.1"): "the reference's city switch dropped the player back to an early "
                          "level; here the level is kept (docs/spec.md section 8)",
}
EVAL_KEYS = ("game", "preset", "agent", "policy", "train_seed", "mean_return", "episodes")
RANDOM_COLUMN = "Random"  # the random policy's column, after the trained agents'


def _read_json_object(path: Path, what: str) -> dict:
    try:
        value = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path} is not valid JSON: {e}") from None
    if not isinstance(value, dict):
        raise ValueError(f"{path} must hold a JSON object ({what}), got {type(value).__name__}")
    return value


def _check_evaluation(path: Path, result: dict) -> None:
    """A clear ValueError if ``result`` is not what ``stori-jax eval`` writes."""
    import stori_jax
    from baselines.evaluate import POLICIES

    missing = [k for k in EVAL_KEYS if k not in result]
    if missing:
        raise ValueError(f"{path} lacks {missing}: not a stori-jax evaluation")
    for key in ("game", "preset"):
        if not isinstance(result[key], str):
            raise ValueError(f"{path}: {key} must be a string, got {result[key]!r}")
    if result["agent"] not in [*agent_names(), RANDOM]:
        raise ValueError(f"{path}: agent must be one of {[*agent_names(), RANDOM]}, got "
                         f"{result['agent']!r}")
    if result["policy"] not in POLICIES or (result["agent"] == RANDOM) != (
            result["policy"] == "random"):
        raise ValueError(f"{path}: policy {result['policy']!r} does not go with agent "
                         f"{result['agent']!r} (random: 'random'; a trained agent: 'sampled' "
                         "or 'greedy')")
    check_int(f"{path}: train_seed", result["train_seed"], 0)
    check_int(f"{path}: episodes", result["episodes"], 1)
    for key, minimum in (("max_episode_frames", 1), ("truncated", 0)):  # older files lack them
        if key in result:
            check_int(f"{path}: {key}", result[key], minimum)
    check_real(f"{path}: mean_return", result["mean_return"])
    try:
        stori_jax.preset(result["game"], result["preset"])
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def load_evaluations(results_dir: Path) -> list[dict]:
    """Every eval-*.json below ``results_dir`` (each must hold the keys of EVAL_KEYS, typed as
    ``stori-jax eval`` writes them)."""
    results_dir = Path(results_dir)
    if not results_dir.is_dir():
        raise ValueError(f"RESULTS_DIR {results_dir} is not a directory")
    found = []
    for path in sorted(results_dir.rglob("eval-*.json")):
        result = _read_json_object(path, "a stori-jax evaluation")
        _check_evaluation(path, result)
        # one spelling per game and preset, so that 'breakout' '3.2c' joins Breakout 3.2C
        game = stori_game(result["game"])
        found.append(dict(result, game=game, preset=canonical_preset(game, result["preset"]),
                          path=str(path), training=_training(result, path)))
    if not found:
        raise ValueError(f"no eval-*.json under {results_dir}: run `stori-jax eval` first")
    return found


def trained_agents(evaluations: list[dict]) -> list[str]:
    """The trained agents with evaluations among ``evaluations``, in AGENT_MODULES' order."""
    found = {e["agent"] for e in evaluations}
    return [name for name in agent_names() if name in found]


def agent_columns(rows: list[dict]) -> list[str]:
    """The trained agents' columns of the table's rows (their titles), in order."""
    skip = {"game", "preset", RANDOM_COLUMN, "DreamerV3", "STORM"}
    return [key for key in rows[0] if key not in skip] if rows else []


def aggregate(evaluations: list[dict], ppo_policy: str = "sampled") -> list[dict]:
    """One row per (game, preset): per agent, the mean over seeds of each seed's mean return,
    and the standard deviation over seeds (ddof=1, as usual for 'mean ± std over 3 seeds').
    A column per trained agent with evaluations (its title), of their ``ppo_policy``
    evaluations (the name is from when PPO was the only agent; it applies to every one), then
    Random."""
    if ppo_policy not in CHECKPOINT_POLICIES:
        raise ValueError(f"ppo_policy must be one of {list(CHECKPOINT_POLICIES)}, "
                         f"got {ppo_policy!r}")
    agents = trained_agents(evaluations)
    titles = {name: get_agent(name).title for name in agents}
    for name in agents:
        policies = {e["policy"] for e in evaluations if e["agent"] == name}
        if ppo_policy not in policies:
            title = titles[name]
            raise ValueError(f"no {title} evaluation with policy {ppo_policy!r}: the {title} "
                             f"evaluations here are {sorted(policies)} (stori-jax eval --policy "
                             f"{ppo_policy} writes one)")
    per_cell = defaultdict(lambda: defaultdict(dict))
    for e in evaluations:
        column = RANDOM_COLUMN if e["agent"] == RANDOM else (
            titles[e["agent"]] if e["policy"] == ppo_policy else None)
        if column is None:
            continue
        seeds = per_cell[(e["game"], e["preset"])][column]
        if e["train_seed"] in seeds:
            raise ValueError(f"two {column} evaluations of {e['game']} {e['preset']} seed "
                             f"{e['train_seed']}: {seeds[e['train_seed']]['path']} and {e['path']}")
        seeds[e["train_seed"]] = e
    rows = []
    for (game, preset), columns in sorted(per_cell.items(), key=lambda kv: _order(*kv[0])):
        row = dict(game=game, preset=preset)
        for column in [*titles.values(), RANDOM_COLUMN]:
            seeds = columns.get(column, {})
            means = [seeds[s]["mean_return"] for s in sorted(seeds)]
            row[column] = dict(
                seeds=sorted(seeds), per_seed=means,
                episodes=[seeds[s]["episodes"] for s in sorted(seeds)],
                # None where an older evaluation did not record it
                max_episode_frames=[seeds[s].get("max_episode_frames") for s in sorted(seeds)],
                truncated=[seeds[s].get("truncated") for s in sorted(seeds)],
                training=[seeds[s]["training"] for s in sorted(seeds)],
                mean=float(np.mean(means)) if means else None,
                std=float(np.std(means, ddof=1)) if len(means) > 1 else None)
        paper = PAPER_RESULTS.get((game, preset))
        row["DreamerV3"] = None if paper is None else dict(mean=paper[0], std=paper[1])
        row["STORM"] = None if paper is None else dict(mean=paper[2], std=paper[3])
        rows.append(row)
    return rows


def _training(result: dict, path: Path) -> dict | None:
    """How far the evaluated checkpoint's run had trained (TRAINING_KEYS): as the evaluation
    recorded it, or, for an older one, from the training run it lies in (its summary.json, or
    its config.json and the last global_step of its log.csv); None where nothing says, and for
    the random policy."""
    from baselines.runs import TRAINING_KEYS

    def checked(values) -> dict | None:
        steps, total, finished = values
        ok = (all(isinstance(v, int) and not isinstance(v, bool) and v >= 0
                  for v in (steps, total)) and isinstance(finished, bool))
        return dict(zip(TRAINING_KEYS, values)) if ok else None

    if result["agent"] == RANDOM:
        return None
    agent = get_agent(result["agent"])
    if all(k in result for k in TRAINING_KEYS):
        return checked([result[k] for k in TRAINING_KEYS])
    run = path.parent
    try:
        summary = json.loads((run / "summary.json").read_text())
        return checked([summary["agent_steps"], summary["config"]["total_steps"],
                        summary["finished"]])
    except (OSError, ValueError, KeyError, TypeError):  # no finished run here, or not ours
        pass
    steps = _logged_last_step(run)
    try:
        config = agent.config_class.from_recorded(json.loads((run / "config.json").read_text()))
    except (OSError, ValueError, KeyError, TypeError):  # no training run here
        return None
    if steps is None:
        return None
    per_iteration = agent.steps_per_iteration(config)
    trained = -(-config.total_steps // per_iteration) * per_iteration  # whole iterations
    return checked([steps, config.total_steps, steps >= trained])


def _order(game: str, preset: str):
    from stori_jax import STORI_GAMES

    rank = STORI_GAMES.index(game) if game in STORI_GAMES else len(STORI_GAMES)
    return (rank, game, preset)


def _cell(entry) -> str:
    if entry is None or entry.get("mean") is None:
        return "-"
    if entry.get("std") is None:
        return f"{entry['mean']:.2f} (1 seed)"
    return f"{entry['mean']:.2f} ± {entry['std']:.2f}"


STD_OVER_SEEDS = ("Ours: mean ± std over seeds of each seed's mean return, the std with "
                  "ddof = 1; the paper's: its mean ± std over seeds 0, 7, 13 (its ddof unstated).")


def markdown(rows: list[dict], ppo_policy: str = "sampled") -> str:
    """The table; its agents' columns name the policy where it is not the default, sampled.
    The seeds column lists the first agent's seeds, and any other column's that differ."""
    agents = agent_columns(rows)
    policy = "" if ppo_policy == "sampled" else f" {ppo_policy}"
    header = [f"{title}{policy} (ours)" for title in agents] + [
        "Random (ours)", "DreamerV3 (paper)", "STORM (paper)",
        f"seeds ({agents[0]})" if agents else "seeds", "episodes per seed"]
    lines = ["| game | preset | " + " | ".join(header) + " |",
             "|---|---|" + "---|" * len(header)]
    columns = [*agents, RANDOM_COLUMN]
    for r in rows:
        base = r[columns[0]]["seeds"]
        seeds = ", ".join(str(s) for s in base)
        for column in columns[1:]:
            if r[column]["seeds"] and r[column]["seeds"] != base:
                seeds += ("; " if seeds else "") + f"{column}: " + ", ".join(
                    str(s) for s in r[column]["seeds"])
        seeds = seeds or "-"
        episodes = sorted(set().union(*(r[column]["episodes"] for column in columns)))
        cells = [_cell(r[column]) for column in columns]
        lines.append(f"| {r['game']} | {r['preset']} | {' | '.join(cells)}"
                     f" | {_cell(r['DreamerV3'])} | {_cell(r['STORM'])} | {seeds} | "
                     f"{', '.join(map(str, episodes))} |")
    return "\n".join(lines) + "\n"


def run_agent(config: dict) -> str:
    """The agent whose run a config.json is: the first of AGENT_MODULES whose config_class
    reads it (each agent's has fields the others' lack; a config of none of them is the first
    agent's, compared as written)."""
    for name in agent_names():
        try:
            get_agent(name).config_class.from_recorded(config)
        except (TypeError, ValueError):
            continue
        return name
    return agent_names()[0]


def learning_curves(results_dir: Path) -> dict[tuple[str, str, str], list[tuple]]:
    """Per (game, preset, agent), per training run: (global_step and return of every episode,
    seed, the run's last agent step, its config)."""
    curves, where = defaultdict(list), defaultdict(dict)
    for path in sorted(Path(results_dir).rglob("episodes.csv")):
        config_path = path.parent / "config.json"
        if not config_path.exists():
            continue
        config = _read_json_object(config_path, "a training run's config")
        missing = [k for k in ("game", "preset", "seed") if k not in config]
        if missing:
            raise ValueError(f"{config_path} lacks {missing}: not a training run's config")
        try:
            seed = check_int("seed", config["seed"], 0, MAX_SEED)
            game = stori_game(config["game"])
            preset = canonical_preset(game, config["preset"])
        except ValueError as e:
            raise ValueError(f"{config_path}: {e}") from None
        try:
            with open(path, newline="") as f:
                reader = csv.DictReader(f)
                rows, columns = list(reader), reader.fieldnames or []
        except (UnicodeDecodeError, csv.Error) as e:
            raise ValueError(f"{path} is not a training run's episodes.csv: {e}") from None
        missing = [k for k in ("global_step", "return") if k not in columns]
        if missing:
            raise ValueError(f"{path} lacks the columns {missing}: not a training run's "
                             "episodes.csv")
        try:
            steps = np.array([int(r["global_step"]) for r in rows], dtype=np.int64)
            returns = np.array([float(r["return"]) for r in rows])
        except (TypeError, ValueError) as e:  # TypeError: a row shorter than the header
            raise ValueError(f"{path}: a global_step or return is not a number ({e})") from None
        panel = (game, preset, run_agent(config))
        curves[panel].append((steps, returns, seed, _last_step(path.parent, steps), config))
        if seed in where[panel]:  # as aggregate() refuses two evaluations of a seed
            raise ValueError(f"two training runs of {game} {preset} seed {seed}: "
                             f"{where[panel][seed]} and {path.parent} (the curves "
                             "would pool both as one seed; move one out of RESULTS_DIR)")
        where[panel][seed] = path.parent
    for runs in curves.values():
        runs.sort(key=lambda run: run[2])
    return curves


def _last_step(run_dir: Path, steps: np.ndarray) -> int:
    """How far a run trained: its log's last global_step (its last episode's, without a log)."""
    end = int(steps.max()) if steps.size else 0
    logged = _logged_last_step(run_dir)
    return end if logged is None else max(end, logged)


def _logged_last_step(run_dir: Path) -> int | None:
    """The last global_step of a run's log.csv (0 before its first row); None without a log
    (or one not of ours)."""
    try:
        with open(run_dir / "log.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        return int(rows[-1]["global_step"]) if rows else 0
    except (OSError, KeyError, TypeError, ValueError):
        return None


def smoothed(steps: np.ndarray, returns: np.ndarray, grid: np.ndarray, window: int,
             end: float = np.inf) -> np.ndarray:
    """Mean return of the ``window`` latest episodes finished by each grid step (NaN before
    the first, and past ``end``, where the run stopped)."""
    out = np.full(grid.shape, np.nan)
    for j, g in enumerate(grid):
        done = returns[steps <= g]
        if done.size and g <= end:
            out[j] = done[-window:].mean()
    return out


def steps_label(value: float, _position) -> str:
    """An axis label of agent steps: 50k, 1.5M (full numbers overlap on a narrow panel)."""
    if abs(value) >= 1e6:
        return f"{value / 1e6:g}M"
    return f"{value / 1e3:g}k" if abs(value) >= 1e3 else f"{value:g}"


def _hyperparameters(config: dict, agent: str) -> dict:
    """A run's config as its ``agent``'s training read it (a field that an older run's
    config.json lacks is its default), without what does not change the training: the seed,
    the checkpoints and the log's rows."""
    try:
        config = dataclasses.asdict(get_agent(agent).config_class.from_recorded(config))
    except (TypeError, ValueError):  # not one of ours: compare it as written
        pass
    return {k: v for k, v in config.items()
            if k not in ("seed", "checkpoint_every", "log_every")}


def paper_notes(rows: list[dict]) -> list[str]:
    """Rows whose paper numbers come from an environment this project corrects."""
    return [f"{r['game']} {r['preset']}: the paper's numbers come from another environment: "
            f"{PAPER_ENVIRONMENT_DIFFERS[r['game'], r['preset']]}" for r in rows
            if (r["game"], r["preset"]) in PAPER_ENVIRONMENT_DIFFERS]


def training_notes(rows: list[dict]) -> list[str]:
    """Trained agents' evaluations that do not stand beside the paper's 100k-step numbers as
    they are: checkpoints of unfinished runs, runs of another budget, and checkpoints whose
    training nothing records."""
    notes = []
    for r, column in ((r, column) for r in rows for column in agent_columns(rows)):
        row = f"{r['game']} {r['preset']} {column}"
        runs = list(zip(r[column]["seeds"], r[column]["training"]))
        unknown = [seed for seed, training in runs if training is None]
        if unknown:
            notes.append(f"{row} seed(s) {unknown}: how far the evaluated checkpoints had "
                         "trained is not recorded")
        known = [(seed, t) for seed, t in runs if t is not None]
        unfinished = [f"seed {seed}: {t['trained_agent_steps']} of {t['run_total_steps']}"
                      for seed, t in known if not t["run_finished"]]
        if unfinished:
            notes.append(f"{row}: checkpoints of unfinished runs ({'; '.join(unfinished)} agent "
                         "steps)")
        for budget in sorted({t["run_total_steps"] for _, t in known} - {PAPER_AGENT_STEPS}):
            seeds = [seed for seed, t in known if t["run_total_steps"] == budget]
            notes.append(f"{row} seed(s) {seeds}: runs of {budget} agent steps (the paper's: "
                         f"{PAPER_AGENT_STEPS})")
    return notes


def evaluation_notes(rows: list[dict]) -> list[str]:
    """Evaluations in the table that a reader should know about: episodes cut off at the frame
    cap (their returns stop there), and a row that compares evaluations under different caps
    (an older evaluation that did not record its cap is left out of that comparison)."""
    notes = []
    for r in rows:
        caps = set()
        for column in [*agent_columns(rows), RANDOM_COLUMN]:
            cell = r[column]
            for seed, episodes, cap, cut in zip(cell["seeds"], cell["episodes"],
                                                cell["max_episode_frames"], cell["truncated"]):
                if cap is not None:
                    caps.add(cap)
                if cut:
                    notes.append(f"{r['game']} {r['preset']} {column} seed {seed}: {cut} of "
                                 f"{episodes} episodes cut off at max_episode_frames {cap} (their "
                                 "returns stop there)")
        if len(caps) > 1:
            notes.append(f"{r['game']} {r['preset']}: the evaluations ran under different frame "
                         f"caps (max_episode_frames {', '.join(map(str, sorted(caps)))})")
    return notes


def _panel_order(panel: tuple[str, str, str]):
    """Curves' panels in the table's order: game, preset, then agent (AGENT_MODULES')."""
    game, preset, agent = panel
    return (*_order(game, preset), agent_names().index(agent))


def table_notes(curves: dict, evaluations: list[dict], ppo_policy: str) -> list[str]:
    """What a reader of the table and the curves should know: training runs the table leaves
    out (no evaluation of ``ppo_policy``), and runs pooled in one panel with different
    hyperparameters.  Where the curves hold runs of several agents, each note names its
    agent."""
    evaluated = {(e["game"], e["preset"], e["agent"], e.get("train_seed")) for e in evaluations
                 if e["agent"] != RANDOM and e.get("policy") == ppo_policy}
    several = len({agent for *_, agent in curves}) > 1
    notes = []
    for (game, preset, agent), runs in sorted(curves.items(),
                                              key=lambda kv: _panel_order(kv[0])):
        where = f"{game} {preset}" + (f" {get_agent(agent).title}" if several else "")
        left_out = [seed for *_, seed, _, _ in runs
                    if (game, preset, agent, seed) not in evaluated]
        if left_out:
            notes.append(f"{where}: seed(s) {left_out} have no eval-{ppo_policy}.json: "
                         "in the curves, not in the table")
        configs = [_hyperparameters(config, agent) for *_, config in runs]
        if len({json.dumps(c, sort_keys=True) for c in configs}) > 1:
            differ = sorted(k for k in set().union(*configs)
                            if len({json.dumps(c.get(k)) for c in configs}) > 1)
            notes.append(f"{where}: the runs pooled in the curves (and, where "
                         f"evaluated, in the table's mean) differ in {', '.join(differ)}")
    return notes


def plot_curves(curves: dict, evaluations: list[dict], out_dir: Path,
                window: int = 20) -> list[Path]:
    """One PNG per game of ``learning_curves``: a panel per preset (a row of them per agent
    where several agents have runs, each panel's title naming its agent), each seed's
    smoothed curve and their mean, with the random policy's evaluation mean as a dashed line
    where one exists."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    random_means = defaultdict(list)
    for e in evaluations:
        if e["agent"] == RANDOM:
            random_means[(e["game"], e["preset"])].append(e["mean_return"])
    written = []
    for game in sorted({g for g, _, _ in curves}, key=lambda g: _order(g, "")):
        presets = sorted({p for g, p, _ in curves if g == game}, key=lambda p: _order(game, p))
        agents = [a for a in agent_names() if any((game, p, a) in curves for p in presets)]
        # one colour per seed in every panel, and one legend for them all
        seeds = sorted({run[2] for (g, _, _), runs in curves.items() if g == game
                        for run in runs})
        colour = {seed: f"C{i % 10}" for i, seed in enumerate(seeds)}
        fig, axes = plt.subplots(len(agents), len(presets),
                                 figsize=(4 * len(presets), 3.2 * len(agents)), squeeze=False,
                                 sharey=True)
        for row, agent in zip(axes, agents):
            named = f"{get_agent(agent).title}: " if len(agents) > 1 else ""
            legend = {}
            for ax, preset in zip(row, presets):
                ax.set_title(f"{named}{game} {preset}")
                ax.set_xlabel("agent steps")
                ax.grid(alpha=0.3)
                runs = curves.get((game, preset, agent), [])
                if not runs:
                    ax.text(0.5, 0.5, "no runs", transform=ax.transAxes, ha="center")
                    continue
                ends = [end for *_, end, _ in runs]
                grid = np.linspace(0, max(max(ends), 1), 100)
                lines, silent = [], []
                for steps, returns, seed, end, _ in runs:
                    line = smoothed(steps, returns, grid, window, end)
                    lines.append(line)
                    if np.isnan(line).all():
                        silent.append(seed)
                    legend[f"seed {seed}"] = ax.plot(grid, line, lw=0.8, alpha=0.5,
                                                     color=colour[seed], label=f"seed {seed}")[0]
                mean = np.mean(np.array(lines), axis=0)  # NaN where a seed has no data: none
                legend["mean over seeds"] = ax.plot(grid, mean, color="black", lw=1.6,
                                                    label="mean over seeds")[0]
                if silent:  # its curve is empty, and so is the mean over seeds
                    ax.text(0.02, 0.97, f"seed(s) {silent}: no finished episode,\nso no mean",
                            transform=ax.transAxes, va="top", fontsize=7,  # over any line
                            bbox=dict(facecolor="white", alpha=0.85, edgecolor="none"),
                            zorder=5)
                if random_means.get((game, preset)):
                    legend["random policy (eval)"] = ax.axhline(
                        np.mean(random_means[(game, preset)]), color="grey", ls="--",
                        label="random policy (eval)")
                ax.set_xlim(0, grid[-1])  # also where no curve has a point
                ax.xaxis.set_major_formatter(FuncFormatter(steps_label))
            row[0].set_ylabel(f"episode return (mean of last {window})")
            order = [f"seed {seed}" for seed in seeds] + ["mean over seeds",
                                                          "random policy (eval)"]
            labels = [label for label in order if label in legend]
            row[-1].legend([legend[label] for label in labels], labels, fontsize=7)
        fig.tight_layout()
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"curves-{game}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def build_table(results_dir: Path, out_dir: Path | None = None,
                ppo_policy: str = "sampled") -> tuple[str, list[Path]]:
    """Write table.md (the table, then the notes), table.json and curves-<game>.png into
    ``out_dir`` (default ``results_dir``), the notes also on stderr; returns (the markdown
    table, the paths written)."""
    results_dir = Path(results_dir)
    out_dir = Path(out_dir) if out_dir is not None else results_dir
    evaluations = load_evaluations(results_dir)
    curves = learning_curves(results_dir)  # read (and checked) before anything is written
    rows = aggregate(evaluations, ppo_policy)
    notes = (table_notes(curves, evaluations, ppo_policy) + paper_notes(rows)
             + training_notes(rows) + evaluation_notes(rows))
    for note in notes:
        print(f"stori-jax table: note: {note}", file=sys.stderr)
    text = markdown(rows, ppo_policy)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "table.md").write_text(text + f"\n{STD_OVER_SEEDS}\n"
                                      + "".join(f"\n- {note}" for note in notes)
                                      + ("\n" if notes else ""))
    (out_dir / "table.json").write_text(json.dumps(dict(ppo_policy=ppo_policy, rows=rows,
                                                        std=STD_OVER_SEEDS, notes=notes),
                                                   indent=1))
    return text, [out_dir / "table.md", out_dir / "table.json",
                  *plot_curves(curves, evaluations, out_dir)]

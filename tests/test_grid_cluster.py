"""``stori-jax grid`` on a Ray cluster that is not one machine's single Ray: a head and two
worker nodes (``ray.cluster_utils.Cluster``: separate raylets, one CPU each, on this machine),
the grid pointed at the head by address.  Its trials spread over the nodes, and a node killed
mid-grid loses nothing: its trial finishes on the other node from its last checkpoint, and the
final table is complete."""

from __future__ import annotations

import json

import pytest

from baselines.commands import run_dir
from baselines.grid.spec import grid_spec

ray = pytest.importorskip("ray", reason="the grid runs on Ray Tune (pip install -e '.[ray]')")
tune = pytest.importorskip("ray.tune")
from ray.cluster_utils import Cluster  # noqa: E402

from baselines.grid.tuning import run_grid  # noqa: E402 (imports Ray)

TINY = ["network=tiny", "num_envs=4", "num_steps=8", "num_minibatches=2", "update_epochs=1"]
PER_ITERATION = 32  # agent steps: 4 envs x 8 steps


@pytest.fixture(scope="module")
def cluster():
    """A head that runs no trial (0 CPUs) and two worker nodes of one CPU each.  Dead nodes
    are noticed within a few seconds (Ray's default health checks take ~30 s)."""
    checks = dict(health_check_initial_delay_ms=0, health_check_period_ms=1000,
                  health_check_failure_threshold=3)
    made = Cluster(initialize_head=True, connect=False,
                   head_node_args=dict(num_cpus=0, include_dashboard=False,
                                       _system_config=checks))
    workers = [made.add_node(num_cpus=1) for _ in range(2)]
    made.wait_for_nodes()
    yield made, workers
    made.shutdown()


class KillANode(tune.Callback):
    """Notes the node of every result; removes the worker node of the first trial that
    reports a training part (its raylet and every process on it die)."""

    def __init__(self, cluster, workers):
        self.cluster, self.workers = cluster, workers
        self.nodes, self.killed, self.recovered = {}, None, 0
        self.reports = {}

    def on_trial_result(self, iteration, trials, trial, result, **info):
        name = f"{result['game']} {result['preset']}"
        self.nodes.setdefault(name, []).append(result["node_id"])
        self.reports.setdefault(name, []).append((result["phase"], result["agent_steps"]))
        if self.killed is None and result["phase"] == "train":
            node = next(n for n in self.workers if n.node_id == result["node_id"])
            self.killed = (name, node.node_id)
            self.cluster.remove_node(node, allow_graceful=False)

    def on_trial_recover(self, iteration, trials, trial, **info):
        self.recovered += 1

    def __getstate__(self):  # Tune saves a run's callbacks with it: the cluster stays here
        return {}


@pytest.mark.slow
def test_trials_spread_over_the_nodes_and_a_lost_node_loses_nothing(cluster, tmp_path):
    made, workers = cluster
    spec = grid_spec("ppo", games=["Breakout"], presets=["1", "3.1"], seeds=[0],
                          steps=2 * PER_ITERATION, eval_episodes=1, max_episode_frames=400,
                          overrides=TINY, parts=2)
    killer = KillANode(made, workers)
    outcome = run_grid(spec, tmp_path, address=made.address, max_failures=2,
                            progress_bar=False, callbacks=[killer])
    assert sorted(outcome.finished) == ["Breakout 1 seed 0", "Breakout 3.1 seed 0"]
    assert not outcome.failed and not outcome.unfinished
    first = {name: nodes[0] for name, nodes in killer.nodes.items()}
    assert set(first.values()) == {w.node_id for w in workers}  # one trial on each node
    lost, dead = killer.killed
    assert killer.recovered == 1
    survivor = next(w.node_id for w in workers if w.node_id != dead)
    assert killer.nodes[lost][-1] == survivor  # it finished on the node left
    # from its checkpoint: its first part is never trained again after the node died
    assert killer.reports[lost] == [("train", 32), ("train", 64), ("done", 64)]
    for preset in ("1", "3.1"):
        run = run_dir(tmp_path, "Breakout", preset, "ppo", 0)
        summary = json.loads((run / "summary.json").read_text())
        assert summary["finished"] and summary["agent_steps"] == 2 * PER_ITERATION
        assert [int(line.split(",")[1]) for line in (run / "log.csv").read_text().split()[1:]
                ] == [32, 64]  # each iteration logged once
    rows = json.loads((tmp_path / "table.json").read_text())["rows"]
    assert [(r["game"], r["preset"], r["PPO"]["seeds"]) for r in rows] == [
        ("Breakout", "1", [0]), ("Breakout", "3.1", [0])]

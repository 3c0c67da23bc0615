"""``stori-jax grid``: the paper's protocol (games x presets x seeds, train, evaluate, the table
beside the paper's) as one Ray Tune experiment, on this machine's cores or on a Ray cluster.

Ray Tune does the work a grid needs and this module writes none of it itself: the trials and
their scheduling over the cluster's CPUs (``tune.Tuner`` over a ``tune.grid_search``, each trial
``tune.with_resources``), their checkpoints (``tune.report(..., checkpoint=...)``, restored with
``tune.get_checkpoint()``), retries of a trial whose process or node died
(``tune.FailureConfig``) and the restore of a stopped experiment (``tune.Tuner.restore``).

One trial is one (game, preset, seed): the agent's ``train`` (the code ``stori-jax train`` runs)
in parts of whole iterations, each part ending with a checkpoint reported to Tune, then
``evaluate`` + ``write_result`` (the code ``stori-jax eval`` runs); the random policy is only
evaluated.  Its files land in ``--out``/<game>-<preset>/<agent>-seed<S>/, as ``stori-jax train
--out`` and ``eval`` write them, so ``stori-jax table --out`` reads a grid's folder as any other;
Tune's own experiment (state, trial logs, checkpoints) lives in ``--out``/tune/.

A resumed run is bit-identical to an uninterrupted one (the agent's checkpoints hold the envs'
snapshots), so a trial interrupted, retried or moved to another node ends with the files that
``stori-jax train`` + ``eval`` give alone, on the same software and machine type.

The package, by job: :mod:`.spec` (what a grid computes, checked), :mod:`.trial` (one trial,
run: no Ray), :mod:`.tuning` (the Tune glue: the trainable, the callback, the experiment),
:mod:`.progress` (the progress bar and the table as trials finish), :mod:`.outcome` (what a
grid did, counted from its folder), :mod:`.cluster` (connecting to Ray) and :mod:`.cli` (the
command).
"""

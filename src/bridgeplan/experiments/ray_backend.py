"""Ray backend: each job (one trained run and its evaluations) is a Ray task with its CPU/GPU needs.

Tasks write their rows into the shared results store themselves (the store is safe for
concurrent writers), so on a cluster the results directory must be on a shared filesystem.
"""

from __future__ import annotations

from bridgeplan.errors import BridgeplanError


def run_ray(jobs, experiments, settings, prior_runs: dict, address: str | None,
            cpus_per_job: int = 1, gpus_per_job: float = 0.0) -> int:
    try:
        import ray
    except ImportError:
        raise BridgeplanError("the ray backend needs the extra: pip install 'bridgeplan[ray]'") from None
    from bridgeplan.experiments.runner import run_job

    try:
        if address:
            ray.init(address=address, ignore_reinit_error=True, log_to_driver=False)
        else:
            ray.init(num_cpus=None, ignore_reinit_error=True, log_to_driver=False, include_dashboard=False)
    except (ConnectionError, RuntimeError, ValueError) as e:
        raise BridgeplanError(f"cannot connect to Ray at {address or 'a local instance'}: {e}") from None
    try:
        task = ray.remote(num_cpus=cpus_per_job, num_gpus=gpus_per_job)(run_job)
        futures = [task.remote(settings, experiments, spec, seed, prior_runs.get(seed, ""), cpus_per_job, False)
                   for spec, seed in jobs]
        return sum(len(rows) for rows in ray.get(futures))
    finally:
        ray.shutdown()

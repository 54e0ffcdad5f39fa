"""Ray backend: each job (one trained run and its evaluations) is a Ray task with its CPU/GPU needs.

Tasks write their rows into the shared results store themselves (the store is safe for
concurrent writers), so on a cluster the results directory must be on a shared filesystem.
"""

from __future__ import annotations

from bridgeplan.errors import BridgeplanError


def connect(address: str | None):
    """Join the Ray cluster at ``address``, or start a local instance; returns the ``ray`` module."""
    try:
        import ray
    except ImportError:
        raise BridgeplanError("the ray backend needs the extra: pip install 'bridgeplan[ray]'") from None
    if address:
        _check_reachable(address)
    try:
        if address:
            ray.init(address=address, ignore_reinit_error=True, log_to_driver=False)
        else:
            ray.init(ignore_reinit_error=True, log_to_driver=False, include_dashboard=False)
    except Exception as e:  # ray raises ConnectionError, RuntimeError, ValueError, its own types...
        raise BridgeplanError(f"cannot connect to Ray at {address or 'a local instance'}: "
                              f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}") from None
    return ray


def run_ray(ray, run_job, jobs, experiments, settings, prior_runs: dict, cpus_per_job: int = 1,
            gpus_per_job: float = 0.0) -> int:
    """Submit ``run_job`` once per (run, seed) job as a Ray task; returns the number of new result rows."""
    task = ray.remote(num_cpus=cpus_per_job, num_gpus=gpus_per_job)(run_job)
    futures = [task.remote(settings, experiments, spec, seed, prior_runs.get(seed, ""), cpus_per_job, False)
               for spec, seed in jobs]
    return sum(len(rows) for rows in ray.get(futures))


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail fast on a ``host:port`` that does not answer (``ray.init`` would retry for minutes)."""
    import socket

    target = address.removeprefix("ray://")
    host, sep, port = target.rpartition(":")
    if not sep or not port.isdigit():
        return  # "auto" or another form ray resolves itself
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as e:
        raise BridgeplanError(f"the Ray cluster at {address} does not answer: {e}") from None

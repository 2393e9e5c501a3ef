"""Experiments from TOML configs: the paper's Table 1 and figures, and new studies.

    from sorjax.experiment import load_config, run_experiment
    res = run_experiment(load_config("configs/table1-quick.toml"), out="runs")
    print(res.table)

The config schema is documented in :mod:`sorjax.experiment._config` (and the
README); ``sorjax experiment CONFIG.toml`` is the command line.
"""

from ._config import METHODS, Config, ConfigError, load_config, parse_config
from ._runner import RunResult, compute_bounds, environment, run_experiment, run_trials
from ._trials import run_trial, trial_seed

__all__ = [
    "METHODS",
    "Config",
    "ConfigError",
    "RunResult",
    "compute_bounds",
    "environment",
    "load_config",
    "parse_config",
    "run_experiment",
    "run_trial",
    "run_trials",
    "trial_seed",
]

"""PPO training of the RL controllers (stable-baselines3), and the export the car runs.

Paper section "ACC-Based Controller": the policy is trained with Proximal Policy Optimization in
the trajectory simulator. `train_policy` runs stable-baselines3's PPO on `PlatoonVecEnv` through
a thin adapter (SB3 has its own vectorised-env interface); `export_policy` writes the actor's
mean-action network as the `.npz` the car evaluates in numpy (`vehicle_agent.controllers.policy`):
the car never installs torch.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from sim.drives import Drive
from sim.folds import drive_date
from sim.recorded import RecordedDrive
from sim.rl.env import EnvConfig, PlatoonVecEnv
from vehicle_agent.controllers.policy import FloatArray, save_policy


@dataclass(frozen=True)
class PpoSettings:
    """PPO hyperparameters (fixed before any evaluation; see docs/simulation.md).

    gamma = 0.995 at 10 Hz looks about 20 s ahead, the time a wave takes to pass a few cars
    behind the AV; tanh MLP 64 x 64, SB3's default, small enough for the car to evaluate in
    microseconds.
    """

    num_envs: int = 16
    n_steps: int = 256
    batch_size: int = 512
    n_epochs: int = 5
    learning_rate: float = 3e-4
    gamma: float = 0.995
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    log_std_init: float = -1.0
    hidden: tuple[int, ...] = (64, 64)

    def trained_timesteps(self, requested: int) -> int:
        """The steps PPO takes when asked for `requested`: it collects whole rollouts of
        n_steps x num_envs steps, so 300,000 asked of 16 x 256 are 303,104 trained."""
        rollout = self.n_steps * self.num_envs
        return -(-requested // rollout) * rollout

    def as_dict(self) -> dict[str, Any]:
        """Plain values for the manifest."""
        values = asdict(self)
        values["hidden"] = list(self.hidden)
        return values


class Sb3Platoons(VecEnv):
    """`PlatoonVecEnv` behind stable-baselines3's VecEnv interface (same-step autoreset both)."""

    def __init__(self, env: PlatoonVecEnv) -> None:
        self.env = env  # before VecEnv's constructor, which asks it for its render mode
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self._actions: FloatArray = np.zeros((env.num_envs, env.action_size))
        self._seed: int | None = None

    def reset(self) -> FloatArray:
        """Start every platoon (seeded once by `seed`)."""
        observation, _ = self.env.reset(seed=self._seed)
        self._seed = None
        return observation

    def seed(self, seed: int | None = None) -> Sequence[None | int]:
        """The next reset draws its drives and windows from `seed`."""
        self._seed = seed
        return [seed] * self.num_envs

    def step_async(self, actions: np.ndarray) -> None:
        """Keep the actions for `step_wait`."""
        self._actions = np.asarray(actions, dtype=np.float64)

    def step_wait(self) -> VecEnvStepReturn:
        """One step of every platoon, with SB3's per-environment infos."""
        observation, reward, terminated, truncated, infos = self.env.step(self._actions)
        done = terminated | truncated
        per_env: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for env in np.flatnonzero(done):
            per_env[env]["terminal_observation"] = infos["final_obs"][env]
            per_env[env]["TimeLimit.truncated"] = bool(truncated[env])
        return observation, reward.astype(np.float32), done, per_env

    def close(self) -> None:
        """Nothing to release."""

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The batched env's attribute, once per environment asked for."""
        return [getattr(self.env, attr_name)] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the batched env."""
        setattr(self.env, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        """Call a method of the batched env once."""
        return [getattr(self.env, method_name)(*method_args, **kwargs)]

    def env_is_wrapped(self, wrapper_class: type[Any], indices: VecEnvIndices = None) -> list[bool]:
        """No gymnasium wrappers here."""
        return [False] * len(list(self._get_indices(indices)))


class _Progress(BaseCallback):
    """Reports the steps done so far to `report` after every rollout."""

    def __init__(self, report: Callable[[int], None]) -> None:
        super().__init__()
        self.report = report

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        self.report(self.num_timesteps)


def stage_progress(
    progress: Callable[[str, int, int], None] | None, stage: str, total: int
) -> Callable[[int], None] | None:
    """`train_policy`'s step counter reported as `progress(stage, done, total)`."""
    if progress is None:
        return None

    def report(done: int) -> None:
        progress(stage, min(done, total), total)

    return report


def recorded_on_dates_of(
    recorded: Sequence[RecordedDrive], drives: Sequence[Drive]
) -> list[RecordedDrive]:
    """The recorded drives of the dates `drives` are of: what a policy trained on `drives` may
    also see with its real INRIX, so that no date held out of its training reaches it so."""
    dates = {drive_date(drive) for drive in drives}
    return [one for one in recorded if drive_date(one.drive) in dates]


def train_policy(
    drives: Sequence[Drive],
    config: EnvConfig,
    settings: PpoSettings,
    timesteps: int,
    seed: int,
    progress: Callable[[int], None] | None = None,
    recorded: Sequence[RecordedDrive] = (),
) -> PPO:
    """PPO on platoons behind `drives` and the recorded drives of their dates (on their real
    INRIX); deterministic for a seed on one machine (1 thread)."""
    torch.manual_seed(seed)
    torch.set_num_threads(1)
    env = Sb3Platoons(
        PlatoonVecEnv(drives, settings.num_envs, config, recorded_on_dates_of(recorded, drives))
    )
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=settings.n_steps,
        batch_size=settings.batch_size,
        n_epochs=settings.n_epochs,
        learning_rate=settings.learning_rate,
        gamma=settings.gamma,
        gae_lambda=settings.gae_lambda,
        clip_range=settings.clip_range,
        ent_coef=settings.ent_coef,
        policy_kwargs={
            "net_arch": {"pi": list(settings.hidden), "vf": list(settings.hidden)},
            "activation_fn": torch.nn.Tanh,
            "log_std_init": settings.log_std_init,
        },
        seed=seed,
        device="cpu",
        verbose=0,
    )
    callback = _Progress(progress) if progress is not None else None
    model.learn(total_timesteps=timesteps, callback=callback)
    return model


def export_policy(model: PPO, path: Path, config: EnvConfig) -> str:
    """Write the actor's mean-action network (tanh MLP, then the action head) to `path`."""
    policy = model.policy
    linear = [
        layer
        for layer in policy.mlp_extractor.policy_net.modules()
        if isinstance(layer, torch.nn.Linear)
    ]
    head = policy.action_net
    if not isinstance(head, torch.nn.Linear):
        raise TypeError(f"the policy's action head is {type(head).__name__}, not a linear layer")
    linear.append(head)
    weights = [layer.weight.detach().cpu().numpy().astype(np.float64).T for layer in linear]
    biases = [layer.bias.detach().cpu().numpy().astype(np.float64) for layer in linear]
    return save_policy(
        path, config.actuation, weights, biases, config.accel_action, config.accel_observation
    )

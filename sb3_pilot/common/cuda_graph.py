"""
The lean update's gradient step as one CUDA graph (``LeanSAC(..., cuda_graphs=True)``, ``UDPO(..., cuda_graphs=True)``):
the critic, actor (UDPO: state planner) and temperature steps with their optimizers, captured once and replayed per
gradient step, with no Python and no kernel launch per operation; the target networks' Polyak update is a second, small
graph. UDPO's periodic refits of its inverse dynamics run eagerly between two replays (``run``'s ``before_step``).

How (as LeanRL captures SAC): the batch lives in static tensors (the sampled batch is copied into them), or, when the
replay buffer is a device-resident :class:`~sb3_pilot.common.buffers.LeanHerReplayBuffer` whose rewards have a device
twin, the draw itself is in the graph; the optimizers are made ``capturable`` (their step counts on the device) with
their learning rates held as device tensors (SB3's schedule is copied into them before each ``train()`` call, so
a captured step follows it); the losses are summed on the device and read once per log dump, not per step. The
first ``WARMUP_STEPS`` gradient steps of each capture run eagerly on a side stream (cuBLAS / cuDNN workspaces,
optimizer state), then the step is captured and replayed. A capture depends on the batch's shapes and on the
parameters' memory: a new batch size (a warning says so), a swapped replay buffer, a moved device-resident buffer or
``set_parameters`` / ``load`` lead to a new capture.

A replayed step draws the same random numbers from the CUDA generator as the eager step from the same state (tested);
its numbers differ from the eager step's by the float rounding of the capturable optimizers (learning rates and bias
corrections as device tensors). A run with ``storage="device"`` draws its batches from torch's generator, not
numpy's, so its random stream is not that of a run with SB3's buffer. :func:`capture_fallback_reason` lists what is
not captured (the model then runs its eager step after a warning): a model off CUDA, gSDE (its noise matrix is drawn
between steps), n-step returns, optimizers without a capturable mode and a model's own reasons (UDPO's
``entropy_term="linearised"``).
"""

import warnings
from collections.abc import Callable
from typing import Any, Protocol

import torch as th
from stable_baselines3.common.buffers import NStepReplayBuffer, ReplayBuffer
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.type_aliases import DictReplayBufferSamples, ReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize

from sb3_pilot.common.buffers import LeanHerReplayBuffer
from sb3_pilot.common.lean import LossRecorder, record_losses

#: Eager gradient steps before each capture
WARMUP_STEPS = 3

Batch = ReplayBufferSamples | DictReplayBufferSamples


class CapturableAlgorithm(Protocol):
    """What :class:`CudaGraphUpdate` needs of an algorithm (``LeanSAC``, ``UDPO``)."""

    device: th.device
    replay_buffer: ReplayBuffer | None
    replay_buffer_class: type[ReplayBuffer] | None
    target_update_interval: int
    _vec_normalize_env: VecNormalize | None

    def _gradient_step(self, replay_data: Any, losses: Any) -> None: ...

    def _update_target_critics(self, gradient_step: int) -> None: ...


def capture_fallback_reason(model: Any, optimizers: list[th.optim.Optimizer], model_reason: str | None = None) -> str | None:
    """
    Why the gradient step of ``model`` cannot be captured as a CUDA graph, or None if it can.

    :param model: the algorithm
    :param optimizers: the optimizers its gradient step steps
    :param model_reason: the algorithm's own reason not to capture its step, if any
    """
    if model.device.type != "cuda":
        return f"the model is on {model.device}, not a CUDA device"
    if model_reason is not None:
        return model_reason
    if getattr(model, "use_sde", False):
        return "gSDE draws its noise matrix between gradient steps"
    buffer_class = model.replay_buffer_class
    if isinstance(buffer_class, type) and issubclass(buffer_class, NStepReplayBuffer):
        return "n-step returns discount each transition by its own horizon, computed when sampling"
    for optimizer in optimizers:
        if "capturable" not in optimizer.defaults or optimizer.defaults.get("differentiable"):
            return f"{type(optimizer).__name__} has no capturable mode"
    return None


class LossAccumulator(LossRecorder):
    """
    A :class:`~sb3_pilot.common.lean.LossRecorder` whose losses are summed on the device, in place (so that a replayed
    graph adds to the same sums), and read from the device only when recorded.
    """

    def __init__(self) -> None:
        super().__init__()
        self._sums: dict[str, th.Tensor] = {}
        #: gradient steps since the last record (each adds every loss once)
        self.n_steps = 0

    def add(self, name: str, value: th.Tensor) -> None:
        """
        :param name: the logger key under ``train/``
        :param value: a scalar (or one-element) tensor
        """
        value = value.detach().reshape(())
        if name not in self._sums:
            if value.is_cuda and th.cuda.is_current_stream_capturing():
                raise RuntimeError(f"Loss {name!r} was not logged by the eager steps before the capture.")
            self._sums[name] = th.zeros_like(value)
        self._sums[name].add_(value)

    def record(self, logger: Logger) -> None:
        """Record the mean of each loss over the steps since the last record as ``train/<name>`` (one host read)."""
        if self.n_steps and self._sums:
            means = (th.stack(list(self._sums.values())) / self.n_steps).tolist()
            th._foreach_zero_(list(self._sums.values()))
            record_losses(logger, dict(zip(self._sums, means, strict=True)))
        self.n_steps = 0


def _tensors(batch: Batch) -> list[th.Tensor]:
    """The tensors of a batch, in a fixed order (observation dicts by key)."""
    tensors: list[th.Tensor] = []
    for value in batch:
        if isinstance(value, dict):
            tensors += [value[key] for key in sorted(value)]
        elif value is not None:
            tensors.append(value)
    return tensors


def _clone(batch: Batch) -> Batch:
    """A batch of fresh tensors with the same values (the static inputs of a capture)."""
    return type(batch)(
        *(
            {key: tensor.clone() for key, tensor in value.items()}
            if isinstance(value, dict)
            else (value.clone() if value is not None else None)
            for value in batch
        )
    )


class CudaGraphUpdate:
    """
    The gradient step of an algorithm (its ``_gradient_step(replay_data, losses)``) and its target update
    (``_update_target_critics``) replayed as CUDA graphs. ``run`` replaces the loop of the algorithm's ``train``
    (after its learning-rate update); the losses go to :attr:`losses`, which the algorithm records when it dumps its
    logs. On a device without graphs (CPU) ``run`` executes the same step on the same static tensors eagerly, which is
    what the tests compare with the algorithm's own step there.

    :param model: the algorithm
    :param optimizers: the optimizers its gradient step steps (made capturable, learning rates as tensors)
    """

    def __init__(self, model: CapturableAlgorithm, optimizers: list[th.optim.Optimizer]):
        self.model = model
        self.optimizers = optimizers
        self.losses = LossAccumulator()
        self._capture = model.device.type == "cuda"
        self._stream = th.cuda.Stream() if self._capture else None
        self._learning_rates: list[tuple[dict[str, Any], th.Tensor, float]] = []
        self._key: tuple[Any, ...] | None = None
        self._captured_batch_size: int | None = None
        self.invalidate()

    @classmethod
    def for_model(
        cls, model: CapturableAlgorithm, optimizers: list[th.optim.Optimizer], model_reason: str | None = None
    ) -> "CudaGraphUpdate | None":
        """
        The captured update of ``model``, or None (and a warning saying why) where it cannot be captured.

        :param model: the algorithm
        :param optimizers: the optimizers its gradient step steps
        :param model_reason: the algorithm's own reason not to capture its step, if any
        """
        reason = capture_fallback_reason(model, optimizers, model_reason)
        if reason is not None:
            warnings.warn(f"cuda_graphs=True: {reason}, so the eager gradient step is used.", stacklevel=3)
            return None
        return cls(model, optimizers)

    def invalidate(self) -> None:
        """Drop the captured graphs (the parameters or the optimizers' state were replaced): the next steps capture anew."""
        self._graph: th.cuda.CUDAGraph | None = None
        self._target_graph: th.cuda.CUDAGraph | None = None
        self._batch: Batch | None = None
        self._warmup_left = WARMUP_STEPS
        self._learning_rates = []

    def _learning_rates_as_tensors(self) -> None:
        """Hold each parameter group's learning rate in a device tensor, set to the float SB3's schedule put there."""
        groups = [group for optimizer in self.optimizers for group in optimizer.param_groups]
        if [id(group) for group, _, _ in self._learning_rates] != [id(group) for group in groups]:
            device = self.model.device
            self._learning_rates = [
                (group, th.full((), float(group["lr"]), device=device), float(group["lr"])) for group in groups
            ]
        for idx, (group, tensor, value) in enumerate(self._learning_rates):
            lr = group["lr"]
            if not isinstance(lr, th.Tensor) and float(lr) != value:
                tensor.fill_(float(lr))
                self._learning_rates[idx] = (group, tensor, float(lr))
            group["lr"] = tensor
        if self._capture:
            for optimizer in self.optimizers:
                for group in optimizer.param_groups:
                    group["capturable"] = True
                    for param in group["params"]:
                        state = optimizer.state.get(param, {})
                        if isinstance(state.get("step"), th.Tensor) and state["step"].device != param.device:
                            state["step"] = state["step"].to(param.device)

    def run(self, gradient_steps: int, batch_size: int, before_step: Callable[[int], None] | None = None) -> None:
        """
        ``gradient_steps`` gradient steps on batches of ``batch_size`` (the loop of ``train``).

        :param gradient_steps: number of gradient steps
        :param batch_size: minibatch size
        :param before_step: called with the step's index before each step, outside the graph (e.g. UDPO's refits of
            its inverse dynamics)
        """
        model = self.model
        buffer = model.replay_buffer
        assert buffer is not None
        env = model._vec_normalize_env
        self._learning_rates_as_tensors()
        for gradient_step in range(gradient_steps):
            if before_step is not None:
                before_step(gradient_step)
            draw_in_graph = self._capture and isinstance(buffer, LeanHerReplayBuffer) and buffer.draws_in_graph
            data: Batch | None = None
            if draw_in_graph:
                assert isinstance(buffer, LeanHerReplayBuffer)
                key: tuple[Any, ...] = ("draw", id(buffer), batch_size, buffer.prepare_draw(env))
            else:
                data = buffer.sample(batch_size, env=env)  # type: ignore[arg-type]
                key = ("copy", batch_size, tuple((tensor.shape, tensor.dtype) for tensor in _tensors(data)))
            if key != self._key:
                self._recapture(key, batch_size)
            if not self._capture:
                self._static_step(data)
            elif self._warmup_left > 0:
                self._warmup_step(buffer, batch_size, data)
            else:
                if self._graph is None:
                    self._capture_graphs(buffer, batch_size, data)
                elif data is not None:
                    self._load(data)
                assert self._graph is not None
                self._graph.replay()
            self.losses.n_steps += 1
            if gradient_step % model.target_update_interval == 0:
                if self._target_graph is not None:
                    self._target_graph.replay()
                else:
                    model._update_target_critics(0)

    def _recapture(self, key: tuple[Any, ...], batch_size: int) -> None:
        """Start over for batches of another kind: drop the graphs, warm up again."""
        if self._captured_batch_size is not None and batch_size != self._captured_batch_size:
            warnings.warn(
                f"The batch size changed from {self._captured_batch_size} to {batch_size} after the gradient step was "
                "captured (its static inputs allocated): it is captured again.",
                stacklevel=3,
            )
        learning_rates = self._learning_rates
        self.invalidate()
        self._learning_rates = learning_rates
        self._key = key

    def _load(self, data: Batch) -> None:
        """Copy a sampled batch into the static input tensors."""
        assert self._batch is not None
        for static, tensor in zip(_tensors(self._batch), _tensors(data), strict=True):
            static.copy_(tensor, non_blocking=True)

    def _static_step(self, data: Batch | None) -> None:
        """The step on the static tensors, run eagerly (devices without graphs)."""
        assert data is not None
        if self._batch is None:
            self._batch = _clone(data)
            self._captured_batch_size = len(data.actions)
        else:
            self._load(data)
        self.model._gradient_step(self._batch, self.losses)

    def _warmup_step(self, buffer: ReplayBuffer, batch_size: int, data: Batch | None) -> None:
        """An eager step on a side stream, as graphs are captured on one."""
        stream = self._stream
        assert stream is not None
        stream.wait_stream(th.cuda.current_stream())
        with th.cuda.stream(stream):
            if data is None:
                assert isinstance(buffer, LeanHerReplayBuffer)
                data = buffer.draw(batch_size)
            self.model._gradient_step(data, self.losses)
        th.cuda.current_stream().wait_stream(stream)

    def _capture_graphs(self, buffer: ReplayBuffer, batch_size: int, data: Batch | None) -> None:
        """Capture the gradient step (the draw too, or reading the static batch) and the target update."""
        if data is not None:
            self._batch = _clone(data)
        for optimizer in self.optimizers:
            # backward() then creates the gradients in the graph's memory, where each replay writes them
            optimizer.zero_grad(set_to_none=True)
        graph = th.cuda.CUDAGraph()
        with th.cuda.graph(graph):
            if self._batch is None:
                assert isinstance(buffer, LeanHerReplayBuffer)
                batch = buffer.draw(batch_size)
            else:
                batch = self._batch
            self.model._gradient_step(batch, self.losses)
        target_graph = th.cuda.CUDAGraph()
        with th.cuda.graph(target_graph, pool=graph.pool()):
            self.model._update_target_critics(0)
        self._graph, self._target_graph = graph, target_graph
        self._captured_batch_size = batch_size

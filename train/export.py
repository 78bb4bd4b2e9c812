"""Export a trained policy as an ONNX graph: raw observations in, the clipped action out.

    python -m train.export runs/ppo_stance --onnx runs/ppo_stance/policy.onnx
    python -m train.export policies/ppo_stance --onnx ppo_stance.onnx

``policy`` is a run or policy folder, read by ``train.evaluate.load_policy`` (so a missing or corrupt
``model.zip``, ``vecnormalize.pkl`` or ``config.yaml`` is an error naming that file). The graph
computes what ``load_policy(folder).predict(obs, deterministic=True)`` computes:

    input  "observation"  float32 (batch, n)    raw observations of the policy's task (n = 12 on the pinned
                                                balance; the task is its run's ``config.yaml`` ``env_id``)
    1. if the run normalised observations (VecNormalize ``norm_obs``):
       clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs), in float64 as VecNormalize
       computes it, then float32 (the shipped policy normalises returns only: no such step)
    2. with ``train.features.CommandGains``, the observation followed by its products with the command entry
       (Slice, Mul, Concat); then the actor: ``mlp_extractor.policy_net`` (Gemm + activation per layer), then ``action_net``,
       the mean of the Gaussian policy, i.e. the deterministic action
    3. clip to the action space, [-1, 1], as SB3's ``predict`` does
    output "action"       float32 (batch, 2)    [hip, knee] in [-1, 1], times ``torque_limit`` N m

The model's doc string and its ``env_id`` metadata name the task (``leg_env.ENV_ID``, the pinned balance, for a
bare ``model.zip`` without a ``config.yaml``, as ``train.evaluate`` assumes).

The graph is written node by node from the network's weights (no tracing through torch's exporter):
it needs only the ``onnx`` package, and reads like the policy. Supported: ``MlpPolicy`` (flat Box
observations, Box actions, ``net_arch`` of any depth, activations Tanh, ReLU, ELU, LeakyReLU, Sigmoid), with SB3's
``FlattenExtractor`` or ``train.features.CommandGains``.
Any ONNX runtime can run it, e.g. ``onnxruntime.InferenceSession(path).run(None, {"observation": obs})``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from leg_env import ENV_ID, __version__
from train.cli import parse_args
from train.policy_loading import PolicyLoadError, TrainedPolicy, load_policy

__all__ = ["ExportArgs", "ExportError", "export_onnx", "policy_to_onnx"]

OPSET = 17  # every op used here has been stable since opset 14; 17 is run by onnxruntime >= 1.13
IR_VERSION = 8  # the ONNX file format of opset 17, readable by older runtimes too
INPUT, OUTPUT = "observation", "action"


class ExportError(ValueError):
    """The policy cannot be written as the ONNX graph described in ``train.export``."""


class _Graph:
    """The nodes and initializers of an ONNX graph being written, each node named by its output."""

    def __init__(self):
        self.nodes, self.initializers = [], []

    def constant(self, name: str, value: np.ndarray) -> str:
        from onnx import numpy_helper

        self.initializers.append(numpy_helper.from_array(np.asarray(value), name))
        return name

    def node(self, op: str, inputs: list[str], output: str, **attributes) -> str:
        from onnx import helper

        self.nodes.append(helper.make_node(op, inputs, [output], name=output, **attributes))
        return output


def policy_to_onnx(policy: TrainedPolicy, source: str = ""):
    """The ONNX model (``onnx.ModelProto``) of ``policy``: raw observations in, clipped actions out."""
    import onnx
    from onnx import TensorProto, helper

    sb3_policy = policy.model.policy
    _check_exportable(sb3_policy)
    env_id = policy.env_id or ENV_ID
    obs_space, action_space = sb3_policy.observation_space, sb3_policy.action_space
    graph = _Graph()
    x = _normalisation(graph, INPUT, policy.vec_normalize)  # policy.vec_normalize: None unless the run normalised observations
    x = _actor(graph, x, sb3_policy)
    low = graph.constant("action_low", action_space.low.astype(np.float32))
    high = graph.constant("action_high", action_space.high.astype(np.float32))
    graph.node("Max", [graph.node("Min", [x, high], "action_below_high"), low], OUTPUT)  # step 3: clipped to the box

    n_obs, n_act = obs_space.shape[0], action_space.shape[0]
    normalised = policy.vec_normalize is not None
    model = helper.make_model(
        helper.make_graph(
            graph.nodes,
            "policy",
            [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, ["batch", n_obs])],
            [helper.make_tensor_value_info(OUTPUT, TensorProto.FLOAT, ["batch", n_act])],
            graph.initializers,
        ),
        opset_imports=[helper.make_opsetid("", OPSET)],
        producer_name="leg-env train.export",
        producer_version=__version__,
        doc_string=(
            f"Deterministic PPO policy for {env_id}: raw float32 observations (batch, {n_obs}) -> actions (batch, {n_act}) "
            f"clipped to [{action_space.low.min():g}, {action_space.high.max():g}]"
            + ("; observations normalised by the run's VecNormalize statistics" if normalised else "")
        ),
    )
    model.ir_version = IR_VERSION
    props = {"env_id": env_id, "source": source, "observation_normalization": "VecNormalize" if normalised else "none"}
    for key, value in props.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(model, full_check=True)
    return model


def _check_exportable(sb3_policy) -> None:
    """``ExportError`` unless the policy is one the module docstring lists as supported."""
    from gymnasium import spaces
    from stable_baselines3.common.torch_layers import FlattenExtractor

    from train.features import CommandGains

    obs_space, action_space = sb3_policy.observation_space, sb3_policy.action_space
    if not (isinstance(obs_space, spaces.Box) and len(obs_space.shape) == 1):
        raise ExportError(f"only flat Box observations can be exported, the model has {obs_space}")
    if not isinstance(action_space, spaces.Box) or len(action_space.shape) != 1:
        raise ExportError(f"only flat Box actions can be exported, the model has {action_space}")
    if sb3_policy.squash_output:
        raise ExportError("policies with squash_output=True are not supported (their actions are tanh-squashed, then unscaled)")
    extractor = sb3_policy.pi_features_extractor
    if not isinstance(extractor, (FlattenExtractor, CommandGains)):
        raise ExportError(f"only MlpPolicy's FlattenExtractor and train.features.CommandGains are supported, the model has {type(extractor).__name__}")


def _normalisation(graph: _Graph, x: str, vec_normalize) -> str:
    """Step 1 of the module docstring: the observation normalised as ``vec_normalize`` does it (None: as it is)."""
    from onnx import TensorProto

    if vec_normalize is None:
        return x
    rms = vec_normalize.obs_rms
    mean, std = np.asarray(rms.mean, dtype=np.float64), np.sqrt(np.asarray(rms.var, dtype=np.float64) + vec_normalize.epsilon)
    clip = float(vec_normalize.clip_obs)
    x = graph.node("Cast", [x], "obs_f64", to=TensorProto.DOUBLE)
    x = graph.node("Sub", [x, graph.constant("obs_mean", mean)], "obs_centred")
    x = graph.node("Div", [x, graph.constant("obs_std", std)], "obs_scaled")
    x = graph.node("Clip", [x, graph.constant("obs_clip_low", np.array(-clip)), graph.constant("obs_clip_high", np.array(clip))],
                   "obs_clipped")  # fmt: skip
    return graph.node("Cast", [x], "obs_normalised", to=TensorProto.FLOAT)


_ACTIVATIONS = {"Tanh": "tanh", "ReLU": "relu", "Sigmoid": "sigmoid"}
"""torch activations without arguments, by class name: their ONNX op (the same name but ReLU's) and node name."""


def _actor(graph: _Graph, x: str, sb3_policy) -> str:
    """Step 2 of the module docstring: the features (``CommandGains``' products), then the actor's layers."""
    import torch

    from train.features import CommandGains

    extractor = sb3_policy.pi_features_extractor
    if isinstance(extractor, CommandGains):  # the observation, then its products with the command entry
        k = extractor.command
        command = graph.node("Slice", [x, graph.constant("command_start", np.array([k])), graph.constant("command_end", np.array([k + 1])),
                                       graph.constant("command_axis", np.array([1]))], "command")  # fmt: skip
        x = graph.node("Concat", [x, graph.node("Mul", [x, command], "command_products")], "features", axis=1)
    for k, layer in enumerate([*sb3_policy.mlp_extractor.policy_net, sb3_policy.action_net]):
        name = type(layer).__name__
        if isinstance(layer, torch.nn.Linear):
            weight = layer.weight.detach().cpu().numpy().astype(np.float32)
            bias = layer.bias.detach().cpu().numpy().astype(np.float32)
            x = graph.node("Gemm", [x, graph.constant(f"W{k}", weight), graph.constant(f"b{k}", bias)], f"linear{k}", transB=1)
        elif isinstance(layer, (torch.nn.Tanh, torch.nn.ReLU, torch.nn.Sigmoid)):
            x = graph.node("Relu" if name == "ReLU" else name, [x], f"{_ACTIVATIONS[name]}{k}")
        elif isinstance(layer, torch.nn.ELU):
            x = graph.node("Elu", [x], f"elu{k}", alpha=float(layer.alpha))
        elif isinstance(layer, torch.nn.LeakyReLU):
            x = graph.node("LeakyRelu", [x], f"leaky_relu{k}", alpha=float(layer.negative_slope))
        elif not isinstance(layer, torch.nn.Identity):
            raise ExportError(f"layer {k} of the actor, {layer}, has no ONNX translation here")
    return x


def export_onnx(policy_dir, out) -> Path:
    """Write the ONNX graph of the policy in ``policy_dir`` (a run or policy folder) to ``out``.

    Raises:
        FileNotFoundError, PolicyLoadError: as ``train.evaluate.load_policy`` (the message names the file).
        ExportError: ``lqr``, or a policy this exporter cannot express.
    """
    import onnx

    if str(policy_dir).lower() == "lqr":
        raise ExportError("'lqr' is the model-based controller (policies/lqr.py), not a network: export a run or policy folder")
    policy = load_policy(policy_dir)
    model = policy_to_onnx(policy, source=Path(policy_dir).as_posix())
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, out)
    return out


@dataclass
class ExportArgs:
    """Export a trained policy as an ONNX graph (raw observations in, clipped actions out)."""

    policy: str
    """Run or policy folder (model.zip, vecnormalize.pkl, config.yaml), or its model.zip."""
    onnx: Path | None = None
    """Output file (None: <policy folder>/policy.onnx)."""


def main(argv: list[str] | None = None) -> None:
    args = parse_args(ExportArgs, argv, positional=("policy",), prog="python -m train.export")
    policy = Path(args.policy)
    out = args.onnx if args.onnx is not None else (policy.parent if policy.suffix == ".zip" else policy) / "policy.onnx"
    try:
        path = export_onnx(args.policy, out)
    except (FileNotFoundError, PolicyLoadError, ExportError) as e:
        raise SystemExit(f"python -m train.export: error: {e}") from None
    import onnx

    print(f"wrote {path}: {onnx.load(path).doc_string}")


if __name__ == "__main__":
    main()

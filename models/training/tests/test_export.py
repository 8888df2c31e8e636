import re
from pathlib import Path

import numpy as np
import onnx
import onnxruntime
import pytest
import torch

from evgate_train.export import INPUT_NAMES, MAX_KEEP_DILATION_PX, OUTPUT_NAMES, export, main
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.sequence import load_sequence
from evgate_train.voxel import voxel_grid

HEIGHT, WIDTH = 48, 96


@pytest.fixture(
    scope="module",
    params=[
        ("half", "global", "bilinear"),
        ("full", "global", "bilinear"),
        ("half", "local", "bilinear"),
        ("half", "global", "convex"),
        ("full", "global", "convex"),
        ("half", "global", "wide-spatial"),
    ],
)
def exported(tmp_path_factory, request):
    """(network, session, path, warp resolution): parity holds for either warp resolution,
    either input normalisation, either flow upsampling, and a wide encoder and mask decoder with
    3x3 gates in every ConvGRU and the mask decoder's global context."""
    torch.manual_seed(1)
    warp_resolution, input_normalisation, variant = request.param
    if variant == "wide-spatial":
        config = NetworkConfig(
            size="XS", mask_decoder_width_factor=2, first_spatial_gru_stage=0, encoder_base_channels=12, global_context=True
        )
    else:
        config = NetworkConfig(size="XS", input_normalisation=input_normalisation, flow_upsampling=variant)
    network = SuppressionNetwork(config).eval()
    # Random, non-zero head weights: freshly initialised refinement heads are zero and would
    # leave parts of the graph untested.
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
    path = tmp_path_factory.mktemp("onnx") / f"tiny-{warp_resolution}-{input_normalisation}-{variant}.onnx"
    export(network, path, HEIGHT, WIDTH, manifest_sha256="ab" * 32, train_steps=12, warp_resolution=warp_resolution)
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    return network, session, path, warp_resolution


def _compare(network, session, warp_resolution: str, voxel: np.ndarray, horizons: list[float], states=None):
    torch_states = [torch.from_numpy(s) for s in states] if states else network.initial_states(1, HEIGHT, WIDTH)
    with torch.no_grad():
        out = network(torch.from_numpy(voxel)[None], torch.tensor([horizons]), torch_states, warp_resolution)
    feeds = {"voxel": voxel[None], "horizons_ms": np.array(horizons, np.float32)}
    feeds.update({f"state_{i}": s.numpy() for i, s in enumerate(torch_states)})
    onnx_out = session.run(OUTPUT_NAMES, feeds)
    expected = [out.mask_logits, out.future_mask_logits, out.coarse_flow, *out.states]
    for name, got, want in zip(OUTPUT_NAMES, onnx_out, expected):
        np.testing.assert_allclose(got, want.numpy(), atol=1e-4, rtol=1e-4, err_msg=name)
    return [s.numpy() for s in out.states]


def test_contract_names_and_metadata(exported):
    network, session, path, warp_resolution = exported
    assert [i.name for i in session.get_inputs()] == INPUT_NAMES
    assert [o.name for o in session.get_outputs()] == OUTPUT_NAMES
    metadata = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    assert metadata["evgate.model-size"] == "XS"
    assert metadata["evgate.state-channels"] == ("12,24,48,96" if network.config.encoder_base_channels else "8,16,32,64")
    assert (metadata["evgate.input-height"], metadata["evgate.input-width"]) == ("48", "96")
    assert metadata["evgate.atc"] == "position-aware"
    assert metadata["evgate.train-steps"] == "12"
    assert metadata["evgate.train-manifest-sha256"] == "ab" * 32
    assert metadata["evgate.warp-resolution"] == warp_resolution
    assert metadata["evgate.flow-stride"] == "8"
    assert metadata["evgate.flow-upsampling"] == network.config.flow_upsampling
    assert metadata["evgate.mask-decoder-width"] == str(network.config.mask_decoder_width)
    assert metadata["evgate.first-spatial-gru-stage"] == str(network.config.first_spatial_gru_stage)
    rule = ("evgate.threshold-logit", "evgate.keep-threshold-logit", "evgate.keep-dilation-px")
    assert tuple(metadata[key] for key in rule) == ("0.0", "0.0", "0")
    # The decoders' convolutions of features + prediction (8 + 1, 8 + 2 channels) were split.
    assert sum(node.name.endswith("/input_part_1") for node in onnx.load(str(path)).graph.node) >= 2
    flow = next(o for o in session.get_outputs() if o.name == "future_flow")
    assert flow.shape[2:] == [2, HEIGHT // 8, WIDTH // 8]
    assert {"evgate.bins", "evgate.window-ms", "evgate.max-horizon-ms", "evgate.base-channels"} <= metadata.keys()


@pytest.mark.parametrize("horizons", [[100.0], [25.0, 50.0, 75.0, 100.0]])
def test_parity_on_random_inputs(exported, horizons):
    network, session, _, warp_resolution = exported
    rng = np.random.default_rng(5)
    states = [rng.standard_normal(tuple(s.shape)).astype(np.float32) * 0.5 for s in network.initial_states(1, HEIGHT, WIDTH)]
    _compare(network, session, warp_resolution, rng.standard_normal((2, HEIGHT, WIDTH)).astype(np.float32), horizons, states)


def test_parity_on_simulated_windows_with_carried_state(exported, synthetic_dir):
    network, session, _, warp_resolution = exported
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    states = None
    for reference in sequence.ref_ts[:3]:
        t_end = int(reference)
        window = sequence.event_range(t_end - 50_000, t_end + 1)
        voxel = voxel_grid(
            sequence.events_t[window], sequence.events_x[window], sequence.events_y[window],
            sequence.events_on[window], t_end, sequence.width, sequence.height,
        )
        states = _compare(network, session, warp_resolution, voxel, [20.0, 100.0], states)


def test_the_command_writes_the_calibrated_mask_rule(tmp_path):
    path = tmp_path / "rule.onnx"
    common = ["--untrained", "--size", "XS", "--height", "48", "--width", "96", "--output", str(path)]
    rule = ("evgate.threshold-logit", "evgate.keep-threshold-logit", "evgate.keep-dilation-px")
    assert main([*common, "--threshold-logit", "-0.5"]) == 0
    metadata = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    assert tuple(metadata[key] for key in rule) == ("-0.5", "-0.5", "0")
    assert main([*common, "--threshold-logit", "-0.5", "--keep-threshold-logit", "1.25", "--keep-dilation-px", "3"]) == 0
    metadata = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    assert tuple(metadata[key] for key in rule) == ("-0.5", "1.25", "3")


@pytest.mark.parametrize("radius", ["-1", "17"])
def test_a_dilation_the_runtime_refuses_is_refused_at_export(tmp_path, radius, capsys):
    with pytest.raises(SystemExit):
        main(["--untrained", "--output", str(tmp_path / "x.onnx"), "--keep-dilation-px", radius])
    assert f"--keep-dilation-px {radius}: expected 0 to 16 pixels" in capsys.readouterr().err
    assert not (tmp_path / "x.onnx").exists()


def test_the_dilation_bound_is_the_runtimes():
    rust = (Path(__file__).parents[3] / "crates/evgate-model/src/metadata.rs").read_text()
    assert re.search(r"pub const MAX_KEEP_DILATION_PX: u16 = (\d+);", rust).group(1) == str(MAX_KEEP_DILATION_PX)

import numpy as np
import onnxruntime
from onnx import TensorProto, helper, numpy_helper

from evgate_train.graph_rewrite import split_concatenated_convolutions


def _model():
    """Three convolutions of concatenations: 3 + 1 channels (split), 8 + 8 (a whole NCHWc
    block, kept) and 3 + 1 depthwise (grouped, kept)."""
    rng = np.random.default_rng(4)
    weights = {
        "w_odd": rng.standard_normal((5, 4, 3, 3)).astype(np.float32),
        "b_odd": rng.standard_normal(5).astype(np.float32),
        "w_block": rng.standard_normal((2, 16, 1, 1)).astype(np.float32),
        "w_depthwise": rng.standard_normal((4, 1, 3, 3)).astype(np.float32),
    }
    nodes = [
        helper.make_node("Concat", ["features", "prediction"], ["odd"], axis=1),
        helper.make_node("Conv", ["odd", "w_odd", "b_odd"], ["out_odd"], name="odd_conv", pads=[1, 1, 1, 1]),
        helper.make_node("Concat", ["wide", "wide"], ["block"], axis=1),
        helper.make_node("Conv", ["block", "w_block"], ["out_block"], name="block_conv"),
        helper.make_node("Concat", ["features", "prediction"], ["grouped"], axis=1),
        helper.make_node("Conv", ["grouped", "w_depthwise"], ["out_depthwise"], name="depthwise", group=4, pads=[1, 1, 1, 1]),
    ]
    inputs = [
        helper.make_tensor_value_info("features", TensorProto.FLOAT, [2, 3, 6, 7]),
        helper.make_tensor_value_info("prediction", TensorProto.FLOAT, [2, 1, 6, 7]),
        helper.make_tensor_value_info("wide", TensorProto.FLOAT, [2, 8, 6, 7]),
    ]
    outputs = [helper.make_tensor_value_info(name, TensorProto.FLOAT, None) for name in ("out_odd", "out_block", "out_depthwise")]
    graph = helper.make_graph(
        nodes, "concat-convs", inputs, outputs, [numpy_helper.from_array(w, name) for name, w in weights.items()]
    )
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])


def _run(model, feeds):
    session = onnxruntime.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    return session.run(None, feeds)


def test_only_the_ungrouped_off_block_convolution_is_split_and_outputs_are_kept():
    rng = np.random.default_rng(5)
    feeds = {
        "features": rng.standard_normal((2, 3, 6, 7)).astype(np.float32),
        "prediction": rng.standard_normal((2, 1, 6, 7)).astype(np.float32),
        "wide": rng.standard_normal((2, 8, 6, 7)).astype(np.float32),
    }
    model = _model()
    before = _run(model, feeds)
    assert split_concatenated_convolutions(model) == 1
    after = _run(model, feeds)
    for name, want, got in zip(("odd", "block", "depthwise"), before, after):
        np.testing.assert_allclose(got, want, atol=1e-5, rtol=1e-5, err_msg=name)
    ops = [node.op_type for node in model.graph.node]
    assert ops.count("Concat") == 2 and ops.count("Conv") == 4 and ops.count("Add") == 1
    initializers = {initializer.name for initializer in model.graph.initializer}
    assert "w_odd" not in initializers and {"w_block", "w_depthwise", "b_odd"} <= initializers

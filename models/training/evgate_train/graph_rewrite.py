"""Export-side rewrite of the ONNX graph: the same function, cheaper on ONNX Runtime's CPU path.

The decoders convolve the concatenation of their features and the previous scale's prediction
(16 + 1 or 16 + 2 channels for S). ONNX Runtime's fast CPU convolution works on channel blocks
of 8 (AVX2) or 16 (AVX-512); with a channel count outside those blocks the convolution falls
back to a slower path, after a full copy for the concatenation. A convolution is linear in its
input channels, so Conv(Concat(a, b), W) = Conv(a, W_a) + Conv(b, W_b): the large part then
takes the fast path and the concatenation disappears. Measured on the S export at K = 8 with 2
threads: 10-20 % less CPU time per call (`git show dd99da7:models/MODEL_CARD.md`, "CPU latency").
"""

import onnx
from onnx import helper, numpy_helper, shape_inference

# Channel counts that are a multiple of this fit ONNX Runtime's NCHWc blocks on AVX2 and AVX-512.
NCHWC_BLOCK = 16


def _channels(shapes: dict[str, onnx.TensorShapeProto], name: str) -> int | None:
    shape = shapes.get(name)
    if shape is None or len(shape.dim) < 2 or not shape.dim[1].HasField("dim_value"):
        return None
    return shape.dim[1].dim_value


def _attribute(node: onnx.NodeProto, name: str, default):
    for attribute in node.attribute:
        if attribute.name == name:
            return helper.get_attribute_value(attribute)
    return default


def split_concatenated_convolutions(model: onnx.ModelProto) -> int:
    """Rewrites, in place, every ungrouped Conv whose input is a channel Concat used by nothing
    else and whose input channel count is not a multiple of `NCHWC_BLOCK` into one Conv per
    concatenated part (the bias on the first) summed by Add. Returns how many were split."""
    graph = model.graph
    initializers = {initializer.name: initializer for initializer in graph.initializer}
    inferred = shape_inference.infer_shapes(model)
    shapes = {
        value.name: value.type.tensor_type.shape
        for value in [*inferred.graph.value_info, *inferred.graph.input, *inferred.graph.output]
    }
    producers = {output: node for node in graph.node for output in node.output}
    uses: dict[str, int] = {}
    for node in graph.node:
        for name in node.input:
            uses[name] = uses.get(name, 0) + 1
    graph_outputs = {output.name for output in graph.output}

    rewritten: list[onnx.NodeProto] = []
    removed_concats: set[str] = set()
    split = 0
    for node in graph.node:
        concat = producers.get(node.input[0]) if node.op_type == "Conv" else None
        weight = initializers.get(node.input[1]) if concat is not None else None
        if (
            concat is None
            or weight is None
            or concat.op_type != "Concat"
            or _attribute(concat, "axis", None) != 1
            or uses[concat.output[0]] != 1
            or concat.output[0] in graph_outputs
            or _attribute(node, "group", 1) != 1
        ):
            rewritten.append(node)
            continue
        parts = [(name, _channels(shapes, name)) for name in concat.input]
        weights = numpy_helper.to_array(weight)
        if any(c is None for _, c in parts) or sum(c for _, c in parts) != weights.shape[1]:
            rewritten.append(node)
            continue
        if weights.shape[1] % NCHWC_BLOCK == 0:
            rewritten.append(node)
            continue
        attributes = {attribute.name: helper.get_attribute_value(attribute) for attribute in node.attribute}
        partial_outputs = []
        start = 0
        for index, (name, channels) in enumerate(parts):
            weight_name = f"{node.name}/input_part_{index}/weight"
            graph.initializer.append(numpy_helper.from_array(weights[:, start : start + channels].copy(), weight_name))
            start += channels
            bias = [node.input[2]] if index == 0 and len(node.input) > 2 else []
            output = f"{node.output[0]}/input_part_{index}"
            rewritten.append(
                helper.make_node("Conv", [name, weight_name, *bias], [output], name=f"{node.name}/input_part_{index}", **attributes)
            )
            partial_outputs.append(output)
        total = partial_outputs[0]
        for index, partial in enumerate(partial_outputs[1:], start=1):
            summed = node.output[0] if index == len(partial_outputs) - 1 else f"{node.output[0]}/sum_{index}"
            rewritten.append(helper.make_node("Add", [total, partial], [summed], name=f"{node.name}/sum_{index}"))
            total = summed
        removed_concats.add(concat.output[0])
        split += 1

    kept = [node for node in rewritten if not (node.op_type == "Concat" and node.output[0] in removed_concats)]
    del graph.node[:]
    graph.node.extend(kept)
    still_used = {name for node in graph.node for name in node.input}
    unused = [initializer for initializer in graph.initializer if initializer.name not in still_used]
    for initializer in unused:
        graph.initializer.remove(initializer)
    return split

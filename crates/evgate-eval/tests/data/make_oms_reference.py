"""Writes oms_reference_worked_example.json: the reference OMS (soykilian/oms_generation, the
EVIMO setting of its main.ipynb) on a small worked example, for tests/oms_reference.rs.

Run beside a checkout of the reference, outside this repository, with a Python that has NumPy
and PyTorch (models/training/.venv):
    git -C REF show HEAD:oms/bin/oms_fixed_kernels/oms.py > ref_oms.py
    git -C REF show HEAD:oms/bin/activation_functions/activation_functions.py > ref_act.py
    python make_oms_reference.py $(git -C REF rev-parse HEAD) oms_reference_worked_example.json
Only the three functions the notebook uses are taken from the reference files, by name, through
ast, so their module-level imports (torchvision, skvideo, h5py) are not needed."""
import ast, json, sys
import numpy as np, torch, torch.nn.functional as F

def load(path, names):
    tree = ast.parse(open(path).read())
    ns = {"np": np, "torch": torch, "F": F}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name in names:
            exec(compile(ast.Module([node], []), path, "exec"), ns)
    return ns

ref = load("ref_oms.py", {"gaussian_filter", "apply_convolution"})
act = load("ref_act.py", {"neuro_activation_function"})

def reference_oms(frame, rc, rs, threshold):
    # oms(): toTensor(filter(radius)) -> (1, k, k) float64 tensor; the frame as a float tensor
    centre_kernel = torch.from_numpy(ref["gaussian_filter"](radius=rc))[None]
    surround_kernel = torch.from_numpy(ref["gaussian_filter"](radius=rs))[None]
    x = torch.from_numpy(frame.astype(np.float32))[None]
    centre = ref["apply_convolution"](x=x, kernel=centre_kernel, stride=1)
    surround = ref["apply_convolution"](x=x, kernel=surround_kernel, stride=1)
    mask = act["neuro_activation_function"](center=centre.numpy(), surround=surround.numpy(), threshold=threshold)
    events = np.abs(centre.numpy() - surround.numpy()).squeeze()
    normalised = (events - events.min()) / events.max()
    return mask.squeeze(), normalised

rng = np.random.default_rng(7)
h, w = 24, 32
frame = np.zeros((h, w), np.uint8)
frame[4:12, 3:13] = rng.random((8, 10)) < 0.6      # a dense textured patch (ego-motion edges)
frame[15:19, 20:24] = 1                            # a solid blob (an object)
frame[2, 20:30] = 1                                 # a line
scatter = rng.random((h, w)) < 0.05                 # noise events
frame |= scatter.astype(np.uint8)
mask, normalised = reference_oms(frame, 2, 4, 0.96)
margin = float(np.min(np.abs(normalised - 0.96)))
json.dump({
    "source": "soykilian/oms_generation@" + sys.argv[1] + ": gaussian_filter, apply_convolution, neuro_activation_function; EVIMO setting of main.ipynb (radii 2 and 4, threshold 0.96)",
    "width": w, "height": h, "centre-radius": 2, "surround-radius": 4, "threshold": 0.96,
    "presence": ["".join("1" if v else "." for v in row) for row in frame],
    "response": [[round(float(v), 6) for v in row] for row in normalised],
    "mask": ["".join("1" if v else "." for v in row) for row in mask],
}, open(sys.argv[2], "w"), indent=1)
print("flagged", int((mask > 0).sum()), "of", h * w, "closest to threshold", margin)

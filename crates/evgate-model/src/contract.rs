//! The graph signature of docs/model-contract.md: input and output names, element types and the
//! fixed dimensions implied by the metadata, checked once at load time.

use ort::value::{Outlet, TensorElementType};

use crate::metadata::{ModelMetadata, STATE_COUNT};

pub const INPUT_VOXEL: &str = "voxel";
pub const INPUT_HORIZONS: &str = "horizons_ms";
pub const INPUT_STATES: [&str; STATE_COUNT] = ["state_0", "state_1", "state_2", "state_3"];
pub const OUTPUT_MASK: &str = "mask_logits";
pub const OUTPUT_FUTURE_MASK: &str = "future_mask_logits";
pub const OUTPUT_FUTURE_FLOW: &str = "future_flow";
pub const OUTPUT_STATES: [&str; STATE_COUNT] =
    ["new_state_0", "new_state_1", "new_state_2", "new_state_3"];

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ContractError {
    #[error("the graph has no {role} named `{name}`; it has: {present}")]
    MissingTensor {
        role: &'static str,
        name: &'static str,
        present: String,
    },
    #[error("{role} `{name}` is {found}; the contract requires a float32 tensor")]
    NotFloatTensor {
        role: &'static str,
        name: &'static str,
        found: String,
    },
    #[error(
        "{role} `{name}` has shape {found:?}; the metadata implies {expected} (-1 marks a dynamic \
         dimension)"
    )]
    ShapeMismatch {
        role: &'static str,
        name: &'static str,
        found: Vec<i64>,
        expected: String,
    },
}

/// A dimension the contract requires: a known size, or `Dynamic` (any size, e.g. K).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Dimension {
    Fixed(i64),
    Dynamic,
}

/// Checks the session's declared inputs and outputs against the contract and the metadata.
pub fn check_signature(
    inputs: &[Outlet],
    outputs: &[Outlet],
    metadata: &ModelMetadata,
) -> Result<(), ContractError> {
    let height = i64::from(metadata.input_height);
    let width = i64::from(metadata.input_width);
    let bins = i64::from(metadata.bins);
    let (flow_height, flow_width) = metadata.flow_size();
    use Dimension::{Dynamic, Fixed};
    check_tensor(
        "input",
        inputs,
        INPUT_VOXEL,
        &[Fixed(1), Fixed(bins), Fixed(height), Fixed(width)],
    )?;
    check_tensor("input", inputs, INPUT_HORIZONS, &[Dynamic])?;
    check_tensor(
        "output",
        outputs,
        OUTPUT_MASK,
        &[Fixed(1), Fixed(1), Fixed(height), Fixed(width)],
    )?;
    check_tensor(
        "output",
        outputs,
        OUTPUT_FUTURE_MASK,
        &[Fixed(1), Dynamic, Fixed(height), Fixed(width)],
    )?;
    check_tensor(
        "output",
        outputs,
        OUTPUT_FUTURE_FLOW,
        &[
            Fixed(1),
            Dynamic,
            Fixed(2),
            Fixed(flow_height as i64),
            Fixed(flow_width as i64),
        ],
    )?;
    for stage in 0..STATE_COUNT {
        let shape = metadata.state_shape(stage).map(|d| Fixed(d as i64));
        check_tensor("input", inputs, INPUT_STATES[stage], &shape)?;
        check_tensor("output", outputs, OUTPUT_STATES[stage], &shape)?;
    }
    Ok(())
}

fn check_tensor(
    role: &'static str,
    outlets: &[Outlet],
    name: &'static str,
    expected: &[Dimension],
) -> Result<(), ContractError> {
    let outlet = outlets
        .iter()
        .find(|outlet| outlet.name() == name)
        .ok_or_else(|| ContractError::MissingTensor {
            role,
            name,
            present: outlets
                .iter()
                .map(Outlet::name)
                .collect::<Vec<_>>()
                .join(", "),
        })?;
    let dtype = outlet.dtype();
    let (Some(TensorElementType::Float32), Some(shape)) =
        (dtype.tensor_type(), dtype.tensor_shape())
    else {
        return Err(ContractError::NotFloatTensor {
            role,
            name,
            found: dtype.to_string(),
        });
    };
    let compatible = shape.len() == expected.len()
        && shape.iter().zip(expected).all(|(&found, want)| match want {
            // A dimension exported as symbolic (-1) still accepts the size we feed.
            Dimension::Fixed(size) => found == *size || found < 0,
            Dimension::Dynamic => true,
        });
    if compatible {
        Ok(())
    } else {
        Err(ContractError::ShapeMismatch {
            role,
            name,
            found: shape.to_vec(),
            expected: describe(expected),
        })
    }
}

fn describe(dimensions: &[Dimension]) -> String {
    let parts: Vec<String> = dimensions
        .iter()
        .map(|dimension| match dimension {
            Dimension::Fixed(size) => size.to_string(),
            Dimension::Dynamic => "K".to_owned(),
        })
        .collect();
    format!("[{}]", parts.join(", "))
}

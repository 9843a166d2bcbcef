//! Why a safetensors file does not parse, told by its tensors. The safetensors crate says
//! "invalid shape, data type, or offset for tensor" or "incomplete metadata, file not fully
//! covered" without naming the tensor or the sizes, which leaves the owner of a truncated or
//! hand-edited checkpoint guessing.

use serde_json::{Map, Value};

/// A sentence naming the first tensor whose bytes do not add up, or the sizes of a truncated
/// or overlong file; `None` where even the header does not read (the crate's own message is
/// then the better one) or nothing is wrong with the layout.
pub fn explain_layout(data: &[u8]) -> Option<String> {
    let n = usize::try_from(u64::from_le_bytes(data.get(..8)?.try_into().ok()?)).ok()?;
    let header: Map<String, Value> =
        serde_json::from_slice(data.get(8..8usize.checked_add(n)?)?).ok()?;
    let body = (data.len() - 8 - n) as u64;
    let mut end = 0u64;
    for (name, t) in header.iter().filter(|(k, _)| *k != "__metadata__") {
        let dtype = t["dtype"].as_str()?;
        let shape: Vec<u64> = t["shape"]
            .as_array()?
            .iter()
            .map(Value::as_u64)
            .collect::<Option<_>>()?;
        let span = t["data_offsets"].as_array()?;
        let (a, b) = (span.first()?.as_u64()?, span.get(1)?.as_u64()?);
        let Some(need) = shape
            .iter()
            .try_fold(dtype_bytes(dtype)?, |acc, d| acc.checked_mul(*d))
        else {
            return Some(format!("tensor `{name}`: shape {shape:?} is too large"));
        };
        if b < a || b - a != need {
            return Some(format!(
                "tensor `{name}`: shape {shape:?} of {dtype} is {need} bytes, but its \
                 data_offsets [{a}, {b}] span {}",
                b.saturating_sub(a)
            ));
        }
        end = end.max(b);
    }
    if end > body {
        Some(format!(
            "the tensors need {end} bytes after the header and the file holds {body}: it is \
             truncated (an interrupted copy?)"
        ))
    } else if end < body {
        Some(format!(
            "{} bytes follow the last tensor's data",
            body - end
        ))
    } else {
        None
    }
}

fn dtype_bytes(dtype: &str) -> Option<u64> {
    Some(match dtype {
        "BOOL" | "U8" | "I8" | "F8_E5M2" | "F8_E4M3" => 1,
        "U16" | "I16" | "F16" | "BF16" => 2,
        "U32" | "I32" | "F32" => 4,
        "U64" | "I64" | "F64" => 8,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use safetensors::{Dtype, tensor::TensorView};

    fn file() -> Vec<u8> {
        let a = [0u8; 24];
        let b = [0u8; 8];
        let views = [
            ("a", TensorView::new(Dtype::F32, vec![2, 3], &a).unwrap()),
            ("b", TensorView::new(Dtype::F64, vec![1], &b).unwrap()),
        ];
        safetensors::serialize(views, None).unwrap()
    }

    #[test]
    fn a_sound_file_has_nothing_to_explain() {
        assert_eq!(explain_layout(&file()), None);
    }

    #[test]
    fn truncation_and_a_misdeclared_tensor_are_named() {
        let data = file();
        let cut = explain_layout(&data[..data.len() - 5]).unwrap();
        assert!(
            cut.contains("truncated") && cut.contains("32 bytes"),
            "{cut}"
        );
        let text = String::from_utf8_lossy(&data).replacen("[2,3]", "[2,4]", 1);
        let wrong = explain_layout(text.as_bytes()).unwrap();
        assert!(
            wrong.contains("tensor `a`") && wrong.contains("32 bytes") && wrong.contains("span 24"),
            "{wrong}"
        );
        let mut long = data;
        long.extend([0u8; 3]);
        assert!(explain_layout(&long).unwrap().contains("3 bytes follow"));
        assert_eq!(explain_layout(b"short"), None);
    }
}

//! A vetting pass over a `.npy` header before npyz parses it. npyz reads the header with a
//! Python-literal parser that takes exponential time in bracket nesting (24 levels: minutes)
//! and multiplies the shape without overflow checks, so a crafted 100-byte file could hang
//! or panic `cocog ingest`. A real header is a flat dict with one shape tuple.

/// Why the header of `bytes` must not be handed to npyz, if it must not.
pub fn vet(bytes: &[u8]) -> Result<(), String> {
    let magic = b"\x93NUMPY";
    if !bytes.starts_with(magic) || bytes.len() < 10 {
        return Err("missing the \\x93NUMPY magic".to_owned());
    }
    let (len, start): (usize, usize) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let header = bytes
        .get(start..start.saturating_add(len))
        .ok_or_else(|| format!("the header claims {len} bytes, past the end of the file"))?;
    let mut depth = 0usize;
    for &b in header {
        match b {
            b'{' | b'(' | b'[' => {
                depth += 1;
                if depth > 2 {
                    return Err("the header nests brackets deeper than a shape tuple".to_owned());
                }
            }
            b'}' | b')' | b']' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    let text = std::str::from_utf8(header).map_err(|_| "the header is not text".to_owned())?;
    let shape = text
        .split_once("'shape'")
        .and_then(|(_, rest)| rest.split_once('(')?.1.split_once(')'))
        .map(|(inside, _)| inside)
        .ok_or_else(|| "the header has no shape tuple".to_owned())?;
    let data = bytes.len() - start - len;
    let mut count: u64 = 1;
    for dim in shape.split(',').map(str::trim).filter(|d| !d.is_empty()) {
        let d: u64 = dim
            .parse()
            .map_err(|_| format!("shape entry {dim:?} is not a size"))?;
        count = count
            .checked_mul(d)
            .filter(|&c| c <= data as u64)
            .ok_or_else(|| {
                format!("shape ({shape}) holds more values than the file's {data} data bytes")
            })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::vet;

    fn npy(header: &str, data: usize) -> Vec<u8> {
        let mut v = b"\x93NUMPY\x01\x00".to_vec();
        v.extend((header.len() as u16).to_le_bytes());
        v.extend(header.as_bytes());
        v.extend(std::iter::repeat_n(0u8, data));
        v
    }

    #[test]
    fn real_headers_pass_and_crafted_ones_are_refused() {
        let ok = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 17), }";
        assert_eq!(vet(&npy(ok, 2 * 17 * 8)), Ok(()));
        let deep = format!(
            "{{'descr': {}1{}, 'shape': (1,)}}",
            "[".repeat(24),
            "]".repeat(24)
        );
        assert!(vet(&npy(&deep, 8)).unwrap_err().contains("nests"));
        let huge = "{'descr': '<f8', 'fortran_order': False, 'shape': (4611686018427387904, 17), }";
        assert!(vet(&npy(huge, 8)).unwrap_err().contains("more values"));
        assert!(vet(b"not npy").is_err());
        let mut cut = npy(ok, 0);
        cut.truncate(20);
        assert!(vet(&cut).unwrap_err().contains("past the end"));
    }
}

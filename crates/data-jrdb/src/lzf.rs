//! LZF (liblzf) block compression, as PCL uses for `DATA binary_compressed`.
//!
//! Format: a run of control bytes. `ctrl < 32`: a literal of `ctrl + 1` bytes follows. Otherwise a
//! back-reference: length `ctrl >> 5` (7 means "add the next byte"), plus 2; offset
//! `((ctrl & 31) << 8 | next byte) + 1` bytes back from the output end.

/// Decompresses `src` into exactly `expected_len` bytes; `Err` describes the corruption.
pub fn decompress(src: &[u8], expected_len: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(expected_len);
    let mut i = 0;
    while i < src.len() {
        let ctrl = src[i] as usize;
        i += 1;
        if ctrl < 32 {
            let n = ctrl + 1;
            if i + n > src.len() {
                return Err(format!("literal of {n} bytes runs past the end of the compressed block"));
            }
            out.extend_from_slice(&src[i..i + n]);
            i += n;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                let Some(&b) = src.get(i) else { return Err("back-reference length cut off".into()) };
                len += b as usize;
                i += 1;
            }
            len += 2;
            let Some(&b) = src.get(i) else { return Err("back-reference offset cut off".into()) };
            i += 1;
            let back = ((ctrl & 31) << 8 | b as usize) + 1;
            if back > out.len() {
                return Err(format!("back-reference {back} bytes before the start of the output"));
            }
            let start = out.len() - back;
            // Byte by byte: an overlapping reference repeats the bytes it is writing.
            for k in 0..len {
                out.push(out[start + k]);
            }
        }
        if out.len() > expected_len {
            return Err(format!("decompresses to more than the declared {expected_len} bytes"));
        }
    }
    if out.len() != expected_len {
        return Err(format!("decompresses to {} bytes, header says {expected_len}", out.len()));
    }
    Ok(out)
}

/// Compresses `src` with a greedy hash-table matcher; the output is valid liblzf input.
pub fn compress(src: &[u8]) -> Vec<u8> {
    const HASH_BITS: u32 = 14;
    const MAX_OFF: usize = 1 << 13;
    const MAX_REF: usize = (1 << 8) + (1 << 3);
    let mut out = Vec::with_capacity(src.len() + src.len() / 16 + 4);
    let mut table = vec![usize::MAX; 1 << HASH_BITS];
    let mut lit: Vec<u8> = Vec::with_capacity(32);
    let flush = |out: &mut Vec<u8>, lit: &mut Vec<u8>| {
        if !lit.is_empty() {
            out.push((lit.len() - 1) as u8);
            out.extend_from_slice(lit);
            lit.clear();
        }
    };
    let hash = |p: &[u8]| -> usize {
        let v = (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32;
        (v.wrapping_mul(2654435761) >> (32 - HASH_BITS)) as usize
    };
    let mut i = 0;
    while i < src.len() {
        if i + 2 < src.len() {
            let h = hash(&src[i..]);
            let cand = table[h];
            table[h] = i;
            if cand != usize::MAX && i - cand <= MAX_OFF && src[cand..cand + 3] == src[i..i + 3] {
                let max = (src.len() - i).min(MAX_REF);
                let mut len = 3;
                while len < max && src[cand + len] == src[i + len] {
                    len += 1;
                }
                flush(&mut out, &mut lit);
                let off = i - cand - 1;
                let l = len - 2;
                if l < 7 {
                    out.push(((l << 5) | (off >> 8)) as u8);
                } else {
                    out.push(((7 << 5) | (off >> 8)) as u8);
                    out.push((l - 7) as u8);
                }
                out.push((off & 0xff) as u8);
                i += len;
                continue;
            }
        }
        lit.push(src[i]);
        if lit.len() == 32 {
            flush(&mut out, &mut lit);
        }
        i += 1;
    }
    flush(&mut out, &mut lit);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_repetitive_and_random_bytes() {
        let mut data: Vec<u8> = (0..5000u32).flat_map(|i| ((i % 97) as f32).to_le_bytes()).collect();
        data.extend((0..3000u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8));
        data.extend(std::iter::repeat_n(7u8, 1000));
        let c = compress(&data);
        assert!(c.len() < data.len());
        assert_eq!(decompress(&c, data.len()).unwrap(), data);
    }

    #[test]
    fn decodes_a_hand_written_block() {
        // literal "abc", then a back-reference of length 5 at offset 3: "abcabcab".
        let block = [2, b'a', b'b', b'c', (3 << 5), 2];
        assert_eq!(decompress(&block, 8).unwrap(), b"abcabcab");
        assert!(decompress(&block, 9).is_err());
        assert!(decompress(&block[..5], 8).is_err());
        assert!(decompress(&[(3 << 5), 9], 5).is_err());
    }
}

//! LZF decompression (liblzf's format), for PCD's `binary_compressed` data.
//!
//! Written here: the `lzf` crate is deprecated and allocates whatever length it is asked for,
//! `lzf-rust` is one release old, and the decoder is twenty lines. Memory is bounded before
//! anything is allocated: LZF expands at most [`MAX_RATIO`] times.

/// The most output bytes one input byte can give: a 3-byte back reference copies 264 bytes.
pub const MAX_RATIO: usize = 88;

/// The `out_len` bytes that `input` decompresses to, or why it does not.
pub fn decompress(input: &[u8], out_len: usize) -> Result<Vec<u8>, String> {
    if out_len > input.len().saturating_mul(MAX_RATIO) {
        return Err(format!(
            "{} compressed bytes cannot hold {out_len} bytes of data",
            input.len()
        ));
    }
    let mut out = Vec::with_capacity(out_len);
    let mut i = 0;
    while i < input.len() {
        let ctrl = input[i] as usize;
        i += 1;
        if ctrl < 32 {
            // A run of ctrl + 1 literal bytes.
            let run = input
                .get(i..i + ctrl + 1)
                .ok_or_else(|| format!("a literal run at byte {} ends past the data", i - 1))?;
            if out.len() + run.len() > out_len {
                return Err(format!(
                    "the data decompresses to more than {out_len} bytes"
                ));
            }
            out.extend_from_slice(run);
            i += run.len();
        } else {
            // A back reference: length (ctrl >> 5) + 2, distance from the 13 bits that follow.
            let at = i - 1;
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *input.get(i).ok_or("a back reference ends past the data")? as usize;
                i += 1;
            }
            let low = *input.get(i).ok_or("a back reference ends past the data")? as usize;
            i += 1;
            let distance = ((ctrl & 0x1f) << 8) + low + 1;
            let len = len + 2;
            let start = out.len().checked_sub(distance).ok_or_else(|| {
                format!("a back reference at byte {at} points before the start of the data")
            })?;
            if out.len() + len > out_len {
                return Err(format!(
                    "the data decompresses to more than {out_len} bytes"
                ));
            }
            // Byte by byte: the copy may overlap what it writes (a run of one repeated byte).
            for k in 0..len {
                out.push(out[start + k]);
            }
        }
    }
    if out.len() != out_len {
        return Err(format!(
            "the data decompresses to {} bytes, not {out_len}",
            out.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_and_back_references_decode() {
        // "abc" literal, then "abcabc" as a reference 3 back of length 6 (overlapping), then a
        // long reference (len 7 + 2 extra) of 11 bytes 1 back.
        let input = [2, b'a', b'b', b'c', (4 << 5), 2, (7 << 5), 2, 0];
        let out = decompress(&input, 3 + 6 + 11).unwrap();
        assert_eq!(out, [&b"abcabcabc"[..], &[b'c'; 11]].concat());
    }

    #[test]
    fn bad_streams_are_errors() {
        assert_eq!(
            decompress(&[1, b'a'], 2).unwrap_err(),
            "a literal run at byte 0 ends past the data"
        );
        assert_eq!(
            decompress(&[0, b'a', (1 << 5), 5], 4).unwrap_err(),
            "a back reference at byte 2 points before the start of the data"
        );
        assert_eq!(
            decompress(&[0, b'a', (7 << 5)], 20).unwrap_err(),
            "a back reference ends past the data"
        );
        assert_eq!(
            decompress(&[1, b'a', b'b'], 1).unwrap_err(),
            "the data decompresses to more than 1 bytes"
        );
        assert_eq!(
            decompress(&[1, b'a', b'b'], 3).unwrap_err(),
            "the data decompresses to 2 bytes, not 3"
        );
        // A length no input of this size can give is refused before anything is allocated.
        assert_eq!(
            decompress(&[0; 4], 4 * MAX_RATIO + 1).unwrap_err(),
            "4 compressed bytes cannot hold 353 bytes of data"
        );
    }

    #[test]
    fn the_largest_expansion_is_reached() {
        // One literal, then a reference of the greatest length (7 + 255 + 2) one back.
        let out = decompress(&[0, b'z', (7 << 5), 255, 0], 1 + 264).unwrap();
        assert_eq!(out.len(), 265);
        assert!(out.iter().all(|&b| b == b'z'));
    }
}

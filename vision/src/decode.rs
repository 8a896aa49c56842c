//! Compressed frame → 8-bit luma, into a buffer reused across frames.
//!
//! JPEG goes through `zune-jpeg` with a luma output colorspace (the decoder skips the chroma
//! planes and the colour conversion: ~4× faster than an RGB round trip). PNG goes through `image`
//! (PNG frames are rare on the hot path; their decode allocates).

use thiserror::Error;
use uavnav_core::ImageFormat;
use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::bytestream::ZCursor;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

/// Why a frame could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// The bytes are not a valid image of the announced format (includes truncated files).
    #[error("corrupt {format} data: {detail}")]
    Corrupt {
        /// Announced format name.
        format: &'static str,
        /// Decoder message.
        detail: String,
    },
    /// The decoded size differs from the configured camera.
    #[error("frame is {got_w}x{got_h}, camera expects {want_w}x{want_h}")]
    SizeMismatch {
        /// Decoded width, px.
        got_w: u32,
        /// Decoded height, px.
        got_h: u32,
        /// Configured width, px.
        want_w: u32,
        /// Configured height, px.
        want_h: u32,
    },
}

/// Decodes frames to luma into an internal buffer reused across calls.
#[derive(Debug)]
pub struct LumaDecoder {
    width: u32,
    height: u32,
    buf: Vec<u8>,
}

impl LumaDecoder {
    /// A decoder for frames of exactly `width × height` pixels.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            buf: vec![0; width as usize * height as usize],
        }
    }

    /// Decodes `data`; on success the luma plane (row-major, `width × height`) is returned.
    pub fn decode(&mut self, format: ImageFormat, data: &[u8]) -> Result<&[u8], DecodeError> {
        let mut buf = std::mem::take(&mut self.buf);
        let res = self.decode_into(format, data, &mut buf);
        self.buf = buf;
        res.map(|()| &self.buf[..])
    }

    /// Decodes `data` into `out` (resized to `width × height`; its allocation is reused), so the
    /// caller can decode straight into its own frame buffer. On error `out` holds garbage.
    pub fn decode_into(
        &mut self,
        format: ImageFormat,
        data: &[u8],
        out: &mut Vec<u8>,
    ) -> Result<(), DecodeError> {
        out.resize(self.width as usize * self.height as usize, 0);
        match format {
            ImageFormat::Jpeg => self.decode_jpeg(data, out),
            ImageFormat::Png => self.decode_png(data, out),
        }
    }

    /// The last luma plane decoded by [`Self::decode`].
    pub fn decode_buffer(&self) -> &[u8] {
        &self.buf
    }

    fn mismatch(&self, w: usize, h: usize) -> DecodeError {
        DecodeError::SizeMismatch {
            got_w: w as u32,
            got_h: h as u32,
            want_w: self.width,
            want_h: self.height,
        }
    }

    fn decode_jpeg(&self, data: &[u8], out: &mut [u8]) -> Result<(), DecodeError> {
        let corrupt = |detail: String| DecodeError::Corrupt {
            format: "jpeg",
            detail,
        };
        // zune-jpeg is lenient with a missing tail (it fills the rest in grey). A frame cut in
        // transit must not become a half-grey measurement, so require the EOI marker.
        if !ends_with_eoi(data) {
            return Err(corrupt("truncated (no end-of-image marker)".into()));
        }
        let opts = DecoderOptions::default()
            .jpeg_set_out_colorspace(ColorSpace::Luma)
            .set_strict_mode(true)
            .set_max_width(16384)
            .set_max_height(16384);
        let mut dec = JpegDecoder::new_with_options(ZCursor::new(data), opts);
        dec.decode_headers()
            .map_err(|e| corrupt(format!("{e:?}")))?;
        let (w, h) = dec
            .dimensions()
            .ok_or_else(|| corrupt("no dimensions".into()))?;
        if (w, h) != (self.width as usize, self.height as usize) {
            return Err(self.mismatch(w, h));
        }
        let need = dec
            .output_buffer_size()
            .ok_or_else(|| corrupt("no output size".into()))?;
        if need != out.len() {
            return Err(corrupt(format!("unexpected output size {need}")));
        }
        dec.decode_into(out).map_err(|e| corrupt(format!("{e:?}")))
    }

    fn decode_png(&self, data: &[u8], out: &mut [u8]) -> Result<(), DecodeError> {
        use image::ImageDecoder;
        let corrupt = |e: image::ImageError| DecodeError::Corrupt {
            format: "png",
            detail: e.to_string(),
        };
        // The header first: a frame announcing another size is refused before the decoder
        // allocates for it (a small PNG can announce a huge image).
        let decoder =
            image::codecs::png::PngDecoder::new(std::io::Cursor::new(data)).map_err(corrupt)?;
        let (w, h) = decoder.dimensions();
        if (w, h) != (self.width, self.height) {
            return Err(self.mismatch(w as usize, h as usize));
        }
        let img = image::DynamicImage::from_decoder(decoder).map_err(corrupt)?;
        let luma = img.into_luma8();
        out.copy_from_slice(luma.as_raw());
        Ok(())
    }
}

/// Whether the JPEG stream ends with the EOI marker (allowing a little trailing padding).
fn ends_with_eoi(data: &[u8]) -> bool {
    let tail = &data[data.len().saturating_sub(64)..];
    tail.windows(2).any(|w| w == [0xFF, 0xD9])
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn gradient_jpeg(w: u32, h: u32) -> Vec<u8> {
        let img =
            image::GrayImage::from_fn(w, h, |x, y| image::Luma([((x * 3 + y * 5) % 256) as u8]));
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode_image(&img)
            .unwrap();
        out
    }

    #[test]
    fn jpeg_png_and_errors() {
        let jpg = gradient_jpeg(64, 48);
        let mut d = LumaDecoder::new(64, 48);
        let y = d.decode(ImageFormat::Jpeg, &jpg).unwrap();
        assert!((i32::from(y[10 * 64 + 10]) - 80).abs() < 6);
        // truncated
        let cut = &jpg[..jpg.len() / 2];
        assert!(matches!(
            d.decode(ImageFormat::Jpeg, cut),
            Err(DecodeError::Corrupt { .. })
        ));
        // wrong size
        let mut d2 = LumaDecoder::new(32, 48);
        assert!(matches!(
            d2.decode(ImageFormat::Jpeg, &jpg),
            Err(DecodeError::SizeMismatch { .. })
        ));
        // garbage
        assert!(d.decode(ImageFormat::Png, &[1, 2, 3]).is_err());
        assert!(d.decode(ImageFormat::Jpeg, &[]).is_err());
        // png
        let img = image::GrayImage::from_fn(64, 48, |x, _| image::Luma([x as u8]));
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let y = d.decode(ImageFormat::Png, &png).unwrap();
        assert_eq!(y[5 * 64 + 7], 7);
    }
}

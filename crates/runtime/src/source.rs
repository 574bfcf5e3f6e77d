//! Capture from a file of interleaved IQ samples: the replay source of the
//! runtime, reading one reply's windows at a time (memory stays bounded by
//! the queues, whatever the recording's length).
//!
//! Layout (what SigMF's `ci16_le` / `cf32_le` with `core:num_channels`
//! interleaved channels stores; the metadata is read elsewhere): sample `s`
//! of channel `c` sits at byte `(s · channels + c) · size`, as int16 I, Q or
//! float32 I, Q, little-endian. Stored values are `scale` times the physical
//! baseband.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::Path;

use num_complex::Complex32;

use crate::pipeline::{Reply, ReplySource};

/// Sample format of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleFormat {
    /// int16 I, int16 Q (SigMF `ci16_le`).
    ComplexI16,
    /// float32 I, float32 Q (SigMF `cf32_le`).
    ComplexF32,
}

impl SampleFormat {
    /// Bytes of one complex sample of one channel.
    pub fn bytes(self) -> usize {
        match self {
            SampleFormat::ComplexI16 => 4,
            SampleFormat::ComplexF32 => 8,
        }
    }
}

/// One reply's window in the file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowSpec {
    /// First sample of the window.
    pub start_sample: u64,
    pub tag: usize,
    /// Window start on the recording's clock, s.
    pub time_s: f64,
    /// First sample's index in the transmitter's stream mod `N`, if known.
    pub tx_phase: Option<usize>,
}

/// Replies read lazily from an interleaved IQ file.
pub struct IqFileReplies {
    file: File,
    format: SampleFormat,
    channels: usize,
    scale: f32,
    window_len: usize,
    windows: std::iter::Peekable<std::vec::IntoIter<WindowSpec>>,
    buffer: Vec<u8>,
    /// Windows that could not be read (I/O error, short file): yielded
    /// with empty windows, so the runtime counts them instead of stopping.
    pub unreadable: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl IqFileReplies {
    /// Opens `path`; every window is `window_len` samples of every channel.
    pub fn open(
        path: &Path,
        format: SampleFormat,
        channels: usize,
        scale: f32,
        window_len: usize,
        windows: Vec<WindowSpec>,
    ) -> std::io::Result<Self> {
        if channels == 0 || window_len == 0 || !(scale.is_finite() && scale > 0.0) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("channels {channels}, window length {window_len} and scale {scale} must be positive"),
            ));
        }
        Ok(Self {
            file: File::open(path)?,
            format,
            channels,
            scale,
            window_len,
            windows: windows.into_iter().peekable(),
            buffer: vec![0; window_len * channels * format.bytes()],
            unreadable: Default::default(),
        })
    }

    fn read(&mut self, spec: &WindowSpec) -> std::io::Result<Vec<Vec<Complex32>>> {
        let size = self.format.bytes();
        let offset = spec.start_sample * (self.channels * size) as u64;
        self.file.read_exact_at(&mut self.buffer, offset)?;
        let mut out = vec![Vec::with_capacity(self.window_len); self.channels];
        let inverse = 1.0 / self.scale;
        for sample in self.buffer.chunks_exact(self.channels * size) {
            for (c, value) in sample.chunks_exact(size).enumerate() {
                let v = match self.format {
                    SampleFormat::ComplexI16 => Complex32::new(
                        i16::from_le_bytes([value[0], value[1]]) as f32,
                        i16::from_le_bytes([value[2], value[3]]) as f32,
                    ),
                    SampleFormat::ComplexF32 => Complex32::new(
                        f32::from_le_bytes([value[0], value[1], value[2], value[3]]),
                        f32::from_le_bytes([value[4], value[5], value[6], value[7]]),
                    ),
                };
                out[c].push(v * inverse);
            }
        }
        Ok(out)
    }
}

impl ReplySource for IqFileReplies {
    fn next_time(&mut self) -> Option<f64> {
        self.windows.peek().map(|w| w.time_s)
    }

    fn next_reply(&mut self) -> Option<Reply> {
        self.next()
    }
}

impl Iterator for IqFileReplies {
    type Item = Reply;

    fn next(&mut self) -> Option<Reply> {
        let spec = self.windows.next()?;
        let windows = match self.read(&spec) {
            Ok(w) => w,
            Err(_) => {
                self.unreadable.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                vec![Vec::new(); self.channels]
            }
        };
        Some(Reply { tag: spec.tag, time_s: spec.time_s, tx_phase: spec.tx_phase, windows })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_interleaved_windows_in_both_formats_and_counts_short_reads() {
        let dir = std::env::temp_dir().join(format!("scattertrack-iq-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // 2 channels, 10 samples: channel c, sample s = (s + 100 c, −s).
        let (channels, samples) = (2usize, 10usize);
        let value = |s: usize, c: usize| ((s + 100 * c) as f32, -(s as f32));
        let mut i16_bytes = Vec::new();
        let mut f32_bytes = Vec::new();
        for s in 0..samples {
            for c in 0..channels {
                let (re, im) = value(s, c);
                i16_bytes.extend((re as i16).to_le_bytes());
                i16_bytes.extend((im as i16).to_le_bytes());
                f32_bytes.extend(re.to_le_bytes());
                f32_bytes.extend(im.to_le_bytes());
            }
        }
        for (name, bytes, format) in
            [("a.ci16", &i16_bytes, SampleFormat::ComplexI16), ("a.cf32", &f32_bytes, SampleFormat::ComplexF32)]
        {
            let path = dir.join(name);
            std::fs::write(&path, bytes).unwrap();
            let specs = vec![
                WindowSpec { start_sample: 2, tag: 1, time_s: 0.5, tx_phase: Some(3) },
                WindowSpec { start_sample: 8, tag: 0, time_s: 0.6, tx_phase: None }, // runs past the end
            ];
            let mut replies = IqFileReplies::open(&path, format, channels, 2.0, 4, specs).unwrap();
            let unreadable = replies.unreadable.clone();
            let first = replies.next().unwrap();
            assert_eq!((first.tag, first.time_s, first.tx_phase), (1, 0.5, Some(3)));
            for c in 0..channels {
                let expected: Vec<Complex32> =
                    (2..6).map(|s| value(s, c)).map(|(re, im)| Complex32::new(re / 2.0, im / 2.0)).collect();
                assert_eq!(first.windows[c], expected);
            }
            let second = replies.next().unwrap();
            assert!(second.windows.iter().all(|w| w.is_empty()));
            assert_eq!(unreadable.load(std::sync::atomic::Ordering::Relaxed), 1);
            assert!(replies.next().is_none());
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}

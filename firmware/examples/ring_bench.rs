//! Cost of reading the converter's DMA ring per sample, on the host: the [`RingReader`] over the
//! software DMA model, in the board's pattern (position extended with the clock's estimate, 32
//! samples per read, the position read again after the copy).
//!
//! ```text
//! cargo build --release -p tribo-firmware --example ring_bench
//! valgrind --tool=callgrind --toggle-collect='*ring_bench*read_all*' \
//!     target/release/examples/ring_bench        # instructions of the reading path only
//! ```
//! Divide the collected instruction count by the sample count the program prints. These are host
//! (x86-64) instructions; the board's figure comes from the emulated Cortex-M7 (QEMU).
use std::hint::black_box;
use std::time::Instant;
use tribo_firmware::acquisition::ring::SCAN_WORDS;
use tribo_firmware::acquisition::{extend_position, DmaModel, RingReader, RING_SCANS, RING_WORDS};

const SAMPLES: u64 = 2_000_000;
/// Samples converted between two reads (1 ms at 10 kS/s).
const PER_POLL: u64 = 10;

#[inline(never)]
fn read_all(dma: &DmaModel<RING_WORDS>, reader: &mut RingReader, out: &mut [[u16; 4]; 32]) -> u64 {
    let mut n = 0;
    loop {
        let w = extend_position(dma.position(), RING_WORDS, dma.written());
        let again = dma.written();
        let b = reader.read(w, dma.ring(), out, || again);
        n += b.len as u64;
        black_box(&out);
        if b.len < out.len() {
            return n;
        }
    }
}

fn main() {
    let mut dma = Box::new(DmaModel::<RING_WORDS>::new());
    let mut reader = RingReader::new(RING_SCANS);
    let mut out = [[0u16; 4]; 32];
    let mut got = 0u64;
    let mut elapsed = std::time::Duration::ZERO;
    let mut k = 0u64;
    while k < SAMPLES {
        for _ in 0..PER_POLL {
            dma.write_scan(&[k as u16, (k >> 16) as u16, 0x8000, 0x1234]);
            k += 1;
        }
        let t = Instant::now();
        got += read_all(&dma, &mut reader, &mut out);
        elapsed += t.elapsed();
    }
    assert_eq!(got, SAMPLES, "every sample read");
    assert_eq!(dma.written(), SAMPLES * SCAN_WORDS as u64);
    println!(
        "{got} samples read, {:.1} ns per sample (wall, host)",
        elapsed.as_nanos() as f64 / got as f64
    );
}

//! The DSP stages of the runtime against the one-thread reply processor,
//! on windows from the DSP crate's test simulator.

#[path = "../../dsp/tests/common/mod.rs"]
#[allow(dead_code)]
mod common;

use num_complex::Complex32;
use scattertrack_dsp::reply::{ReplyOptions, ReplyProcessor};
use scattertrack_runtime::dsp::{BufferPool, DspSetup};
use scattertrack_runtime::{AntennaWorker, Reply, ReplyFusion, ReplyHeader};

#[test]
fn workers_cut_every_antenna_to_the_symbols_all_antennas_have() {
    // Learn the per-rx timing reference D_r on one reply.
    let mut reply = common::Reply::paper(3);
    let windows = reply.windows();
    let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();
    let mut processor = ReplyProcessor::new(reply.config.clone(), reply.symbol.clone(), ReplyOptions::default()).unwrap();
    processor.process(&refs, Some(reply.tx_phase)).unwrap();
    let reference = processor.timing_reference().expect("learnt").to_vec();
    let n = reply.config.subcarriers;
    assert!(reference.iter().any(|&d| d != reference[0]), "the rx need different delays: {reference:?}");

    // A reply whose windows start on rx 0's symbol boundary: 30 000 samples
    // hold 1500 whole symbols on rx 0 and 1499 on the others.
    reply.tx_phase = reference[0] % n;
    reply.seed = 4;
    let windows = reply.windows();
    let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();
    let setup = DspSetup {
        config: reply.config.clone(),
        symbol: reply.symbol.clone(),
        options: ReplyOptions::default(),
        timing_reference: Some(reference.clone()),
        correction: None,
        ema_alpha: None,
    };
    setup.validate(windows.len()).unwrap();
    let pool = BufferPool::default();
    let mut worker = setup.worker(&pool).unwrap();
    let runtime_reply = Reply { tag: 0, time_s: 0.0, tx_phase: Some(reply.tx_phase), windows: windows.clone() };
    let outputs: Vec<_> = (0..windows.len()).map(|slot| worker.process(slot, &runtime_reply)).collect();
    let counts: Vec<usize> = outputs.iter().map(|o| o.symbol_sums.symbols).collect();
    assert_eq!(counts, vec![1499; windows.len()], "every antenna cut to the common span");
    assert_eq!(outputs[0].first_sample, 0);

    // Fusion of the cut antennas = the one-thread processor, which
    // truncates to the common span itself.
    let mut fusion = setup.fusion(&pool).unwrap();
    let header = ReplyHeader { index: 0, tag: 0, time_s: 0.0, tx_phase: Some(reply.tx_phase) };
    let fused = fusion.fuse(&header, outputs).unwrap();
    let mut one_thread = ReplyProcessor::new(reply.config.clone(), reply.symbol.clone(), ReplyOptions::default()).unwrap();
    one_thread.set_timing_reference(Some(reference)).unwrap();
    let expected = one_thread.process(&refs, Some(reply.tx_phase)).unwrap();
    assert_eq!(expected.symbols, 1499);
    let f_count = expected.subcarriers;
    for (a, channel) in fused.iter().enumerate() {
        let channel = channel.as_ref().expect("every antenna estimated");
        for (got, want) in channel.iter().zip(&expected.tag_channel[a * f_count..(a + 1) * f_count]) {
            assert!((got - want).norm() <= 1e-9 * want.norm().max(1e-12), "rx {a}: {got} vs {want}");
        }
    }
}

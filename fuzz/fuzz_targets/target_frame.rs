//! The power-up spectra frame decoder, then the re-identification on what it accepts.
#![no_main]
use ferrosid::cli::reidentify::reidentify;
use ferrosid::rational_fit::RationalFitOptions;
use ferrosid::target_frame::TargetFrame;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(f) = TargetFrame::parse(&text, std::path::Path::new("fuzz/target.log")) {
        let _ = f.gated_h1(0.5, 1e-6);
        let _ = reidentify(&f, &RationalFitOptions::new(2, 1, 1), 0..=2, None, 1e-6);
    }
});

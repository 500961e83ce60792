//! Headerless whitespace-separated text logs (DaISy .dat).
#![no_main]
use ferrosid::io::{read_columns, TextOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let p = ferrosid_fuzz::scratch_file("dat", data);
    let _ = read_columns(
        &p,
        &TextOptions {
            input_cols: vec![1],
            output_cols: vec![2],
            fs: Some(1.0),
            ..TextOptions::default()
        },
    );
});

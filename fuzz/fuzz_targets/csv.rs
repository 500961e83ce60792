//! CSV log reader: any bytes give a log or an error, never a panic or a hang.
#![no_main]
use ferrosid::io::{read_csv, CsvOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let p = ferrosid_fuzz::scratch_file("csv", data);
    let _ = read_csv(&p, &CsvOptions::default());
    let _ = read_csv(
        &p,
        &CsvOptions {
            fs: Some(1000.0),
            ..CsvOptions::default()
        },
    );
});

//! MATLAB v5 .mat reader: any bytes give variables or an error.
#![no_main]
use ferrosid::io::{read_mat, MatFile, MatOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let p = ferrosid_fuzz::scratch_file("mat", data);
    if let Ok(m) = MatFile::open(&p) {
        for v in m.variables().to_vec() {
            let _ = m.array(&v.name);
            let _ = m.scalar(&v.name);
        }
    }
    let _ = read_mat(
        &p,
        &MatOptions {
            inputs: vec!["u".into()],
            outputs: vec!["y".into()],
            fs: Some(100.0),
            ..MatOptions::default()
        },
    );
});

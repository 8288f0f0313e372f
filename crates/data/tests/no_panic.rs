//! Property test: no bytes make a reader panic. Random bytes and random
//! mutations of valid files (truncation, flipped bytes, inserted separators
//! and line ends, deleted spans) go to the Qualisys importer, the recorded
//! simulator importer and the run-CSV reader; each must return Ok or Err.

use proptest::prelude::*;
use realitygap_data::parse_run_csv;
use realitygap_data::qualisys::{self, QualisysOptions};
use realitygap_data::recorded::{self, QuatOrder, RecordedOptions};
use std::path::Path;

/// A small valid headerless Qualisys file in the study's layout.
fn qualisys_seed() -> Vec<u8> {
    let body = "-9.79103\t52.98164\t874.12947\t-179.84204\t2.60642\t-2.43220\t0.60391\t0.99807\t0.04231\t0.04555\t\
                0.04239\t-0.99910\t-0.00082\t0.04547\t0.00275\t-0.99896";
    let mut s = String::new();
    for i in 0..4 {
        s.push_str(&format!(
            "{}\t{:.5}\t{body}\t\t{body}\t\t{body}\t\r\n",
            i + 1,
            i as f64 / 100.0
        ));
    }
    s.into_bytes()
}

/// A small valid Qualisys file with its header block.
fn qualisys_header_seed() -> Vec<u8> {
    let body = "501.08185\t6.15862\t41.20390\t1.01749\t-0.79782\t-0.28554\t0.23964\t0.99989\t-0.00523\t0.01383\t\
                0.00498\t0.99983\t0.01783\t-0.01392\t-0.01776\t0.99975";
    let names = "X\tY\tZ\tRoll\tPitch\tYaw\tResidual\tRot[0]\tRot[1]\tRot[2]\tRot[3]\tRot[4]\tRot[5]\tRot[6]\tRot[7]\tRot[8]\t";
    let mut s = String::from(
        "NO_OF_FRAMES\t3\r\nFREQUENCY\t100\r\nDATA_INCLUDED\t6D\r\nBODY_NAMES\tA\tB\r\n",
    );
    s.push_str(&format!("A {names}\tB {names}\r\n"));
    for _ in 0..3 {
        s.push_str(&format!("{body}\t\t{body}\t\r\n"));
    }
    s.into_bytes()
}

fn recorded_seed() -> Vec<u8> {
    let row = "0.0031402040602025692 0.06670811767548805 0.8718734362017465 -0.0008268372737291811 \
               0.9995163273929321 0.030289790062052308 0.006996873091936217 0.5 1.7483063550833285e-19 \
               0.041705196186845324 1.0 1.9393606004525326e-18 0.0 0.0\r\n";
    row.repeat(4).into_bytes()
}

fn run_csv_seed() -> Vec<u8> {
    b"t_s,wrist_x_m,wrist_y_m,wrist_z_m,wrist_qw,wrist_qx,wrist_qy,wrist_qz,q1_rad,qd_cmd1_rad_s\n\
      0,0.1,0.2,0.3,1,0,0,0,0.5,-0.1\n0.05,,,,,,,,0.6,NaN\n0.1,1e17,-inf,2e-19,0.5,0.5,0.5,0.5,0.7,0\n"
        .to_vec()
}

#[derive(Debug, Clone)]
enum Mutation {
    Truncate(usize),
    Flip(usize, u8),
    Insert(usize, u8),
    Delete(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let separator = prop::sample::select(vec![
        b'\t', b'\n', b'\r', b',', b' ', b'-', b'.', b'e', b'0', 0xff, 0,
    ]);
    prop_oneof![
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Flip(i, b)),
        (any::<usize>(), separator).prop_map(|(i, b)| Mutation::Insert(i, b)),
        (any::<usize>(), 1usize..40).prop_map(|(i, n)| Mutation::Delete(i, n)),
    ]
}

fn apply(mut bytes: Vec<u8>, mutations: &[Mutation]) -> Vec<u8> {
    for m in mutations {
        let len = bytes.len();
        match *m {
            Mutation::Truncate(i) => bytes.truncate(i % (len + 1)),
            Mutation::Flip(i, b) if len > 0 => bytes[i % len] = b,
            Mutation::Flip(..) => {}
            Mutation::Insert(i, b) => bytes.insert(i % (len + 1), b),
            Mutation::Delete(i, n) if len > 0 => {
                let start = i % len;
                bytes.drain(start..(start + n).min(len));
            }
            Mutation::Delete(..) => {}
        }
    }
    bytes
}

fn feed_all(bytes: &[u8]) {
    let file = Path::new("fuzz");
    let _ = qualisys::parse(bytes, file, &QualisysOptions::collins2019());
    let _ = qualisys::parse(bytes, file, &QualisysOptions::default());
    let _ = recorded::parse(bytes, file, &RecordedOptions::new(QuatOrder::Xyzw));
    let _ = recorded::parse(bytes, file, &RecordedOptions::new(QuatOrder::Wxyz));
    let _ = parse_run_csv(bytes, file);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        feed_all(&bytes);
    }

    #[test]
    fn random_text_never_panics(text in "[0-9\t\r\n ,.eE+-]{0,400}|[A-Za-z_0-9\t\r\n ()\\[\\]]{0,200}") {
        feed_all(text.as_bytes());
    }

    #[test]
    fn mutated_valid_files_never_panic(
        seed in 0usize..4,
        mutations in prop::collection::vec(mutation(), 1..5),
    ) {
        let base = match seed {
            0 => qualisys_seed(),
            1 => qualisys_header_seed(),
            2 => recorded_seed(),
            _ => run_csv_seed(),
        };
        let bytes = apply(base, &mutations);
        feed_all(&bytes);
    }
}

/// The seeds themselves are valid, so mutations start from real input.
#[test]
fn seeds_are_valid() {
    let file = Path::new("seed");
    let run = qualisys::parse(&qualisys_seed(), file, &QualisysOptions::collins2019()).unwrap();
    assert_eq!(run.trajectory.len(), 4);
    let run = qualisys::parse(&qualisys_header_seed(), file, &QualisysOptions::default()).unwrap();
    assert_eq!(run.trajectory.len(), 3);
    assert!(run.warnings.is_empty(), "{:?}", run.warnings);
    let run = recorded::parse(
        &recorded_seed(),
        file,
        &RecordedOptions::new(QuatOrder::Xyzw),
    )
    .unwrap();
    assert_eq!(run.trajectory.len(), 4);
    assert_eq!(parse_run_csv(&run_csv_seed(), file).unwrap().len(), 3);
}

//! The golden runs: a short CartPole run, `data/golden-cartpole.toml`, must
//! give the committed `data/golden-cartpole-episodes.csv` to the byte, and the same run with the
//! SVM demonstration model `data/golden-cartpole-svm-episodes.csv`:
//! - with the widest products the CPU has (AVX-512 or AVX2+FMA);
//! - with glibc's FMA and AVX2 code paths masked (`GLIBC_TUNABLES`), as on a CPU without them:
//!   the core's `exp`, `ln`, `pow`, `sin` and `cos` come from the `libm` crate, not glibc, whose
//!   choice of implementation by CPU features would make this run's numbers differ between
//!   CPUs from episode 129;
//! - with the portable fallback of the products (`ALFD_PORTABLE_KERNELS=1`: a correctly rounded
//!   software FMA per element), over the first 1,500 steps (it is slow).
//!
//! A difference means the arithmetic now depends on the CPU (or the code changed the numbers: then
//! regenerate the files and the committed results, and say so).

use crate::support::{alfd, text, timed, tmp};

const CONFIG: &str = "deploy/cli/tests/data/golden-cartpole.toml";
const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/");
/// What glibc may use on a CPU without AVX2 and FMA (and AVX-512, FMA4).
const NO_FMA: &str = "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F,-FMA4";

#[derive(Clone, Copy, Debug)]
enum Arithmetic {
    Avx2Fma,
    GlibcWithoutFma,
    PortableKernels,
}

/// Runs the golden config with `sets` under `arithmetic` and compares its `episodes.csv` with
/// the committed `golden` file (the first rows only for the portable kernels).
fn check(golden: &str, sets: &[&str], arithmetic: Arithmetic) {
    let golden = std::fs::read_to_string(format!("{DATA}{golden}")).unwrap();
    let out = tmp(&format!("golden-{arithmetic:?}"));
    let mut c = alfd();
    c.args(["local", "--config", CONFIG, "--quiet"])
        .arg(format!("--out={}", out.display()));
    for s in sets {
        c.args(["--set", s]);
    }
    c.env_remove("ALFD_PORTABLE_KERNELS")
        .env_remove("GLIBC_TUNABLES");
    let partial = matches!(arithmetic, Arithmetic::PortableKernels);
    match arithmetic {
        Arithmetic::Avx2Fma => {}
        Arithmetic::GlibcWithoutFma => {
            c.env("GLIBC_TUNABLES", NO_FMA);
        }
        Arithmetic::PortableKernels => {
            c.env("ALFD_PORTABLE_KERNELS", "1")
                .args(["--set", "steps=1500"]);
        }
    }
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let got = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    let rows = got.lines().count();
    assert!(rows > 20, "{rows} rows");
    let first_diff = golden
        .lines()
        .zip(got.lines())
        .position(|(a, b)| a != b)
        .map(|i| {
            format!(
                "line {}: {:?} vs {:?}",
                i + 1,
                golden.lines().nth(i),
                got.lines().nth(i)
            )
        });
    assert_eq!(first_diff, None, "{arithmetic:?}, {sets:?}");
    if !partial {
        assert_eq!(got, golden, "{arithmetic:?}, {sets:?}");
    }
}

#[test]
fn the_golden_run_gives_the_committed_episodes_csv_on_every_kernel() {
    let _time = timed!();
    let golden = std::fs::read_to_string(format!("{DATA}golden-cartpole-episodes.csv")).unwrap();
    assert_eq!(golden.lines().count(), 84, "83 episodes and the header");
    for arithmetic in [
        Arithmetic::Avx2Fma,
        Arithmetic::GlibcWithoutFma,
        Arithmetic::PortableKernels,
    ] {
        check("golden-cartpole-episodes.csv", &[], arithmetic);
    }
}

#[test]
fn the_golden_run_with_the_svm_model_gives_its_committed_episodes_csv_without_fma_too() {
    let _time = timed!();
    for arithmetic in [Arithmetic::Avx2Fma, Arithmetic::GlibcWithoutFma] {
        check(
            "golden-cartpole-svm-episodes.csv",
            &["expert.model=svm"],
            arithmetic,
        );
    }
}

//! The golden run (issue 14, item 3): a short CartPole run, `data/golden-cartpole.toml`, must
//! give the committed `data/golden-cartpole-episodes.csv` to the byte, with the AVX2+FMA products
//! and again with the portable fallback (`ALFD_PORTABLE_KERNELS=1`: a correctly rounded software FMA
//! per element). A difference means the arithmetic now depends on the CPU (or the code changed
//! the numbers: then regenerate the file and the committed results, and say so).

use crate::support::{alfd, text, timed, tmp};

const CONFIG: &str = "deploy/tests/data/golden-cartpole.toml";
const GOLDEN: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/data/golden-cartpole-episodes.csv"
);

#[test]
fn the_golden_run_gives_the_committed_episodes_csv_on_every_kernel() {
    let _time = timed!();
    let golden = std::fs::read_to_string(GOLDEN).unwrap();
    assert_eq!(golden.lines().count(), 84, "83 episodes and the header");
    // The fallback is slow (a software FMA per element): it plays the first 1,500 steps, whose
    // episodes must be the golden run's first ones.
    for (scalar, steps) in [(false, None), (true, Some(1500))] {
        let out = tmp(if scalar { "golden-scalar" } else { "golden" });
        let mut c = alfd();
        c.args(["local", "--config", CONFIG, "--quiet"])
            .arg(format!("--out={}", out.display()));
        if let Some(n) = steps {
            c.args(["--set", &format!("steps={n}")]);
        }
        if scalar {
            c.env("ALFD_PORTABLE_KERNELS", "1");
        } else {
            c.env_remove("ALFD_PORTABLE_KERNELS");
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
        assert_eq!(first_diff, None, "scalar fallback: {scalar}");
        if steps.is_none() {
            assert_eq!(got, golden);
        }
    }
}

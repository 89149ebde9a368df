//! TensorBoard's event files, written by hand from the format's own definition (pure: bytes out).
//!
//! A file is a sequence of records: the data's length as a little-endian `u64`, the masked
//! CRC-32C of those 8 bytes, the data, the masked CRC-32C of the data. Each record's data is an
//! `Event` protocol buffer: `wall_time` (field 1, double), `step` (field 2, int64) and either
//! `file_version` (field 3, the first event: `brain.Event:2`) or a `Summary` (field 5) of
//! `Value`s, each a `tag` (field 1) and a `simple_value` (field 2, float).
//!
//! [`EpisodeScalars`] turns the run's episodes into the scalars a Stable-Baselines3 user reads
//! (`rollout/ep_rew_mean`, `rollout/ep_len_mean`, `eval/mean_reward`, `time/fps`), then this
//! project's own (`query/js`, `query/gate_fired`, `demos/used`, `demos/budget_left`,
//! `actor/<id>/sps`), each at the run's environment step.

use std::collections::{BTreeMap, VecDeque};

use crate::record::EpisodeRecord;

/// The version the first event of a file names.
pub const FILE_VERSION: &str = "brain.Event:2";

/// Episodes in the rolling means, as Stable-Baselines3's `ep_info_buffer`.
pub const ROLLING: usize = 100;

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78) of `bytes`.
pub fn crc32c(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0x82F6_3B78 & mask);
        }
    }
    !crc
}

/// The masked CRC the record format stores.
pub fn masked_crc(bytes: &[u8]) -> u32 {
    let crc = crc32c(bytes);
    (crc.rotate_right(15)).wrapping_add(0xa282_ead8)
}

/// `data` framed as one record.
pub fn record(data: &[u8]) -> Vec<u8> {
    let len = (data.len() as u64).to_le_bytes();
    let mut out = Vec::with_capacity(data.len() + 16);
    out.extend_from_slice(&len);
    out.extend_from_slice(&masked_crc(&len).to_le_bytes());
    out.extend_from_slice(data);
    out.extend_from_slice(&masked_crc(data).to_le_bytes());
    out
}

fn varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// A length-delimited field.
fn bytes_field(field: u64, bytes: &[u8], out: &mut Vec<u8>) {
    varint(field << 3 | 2, out);
    varint(bytes.len() as u64, out);
    out.extend_from_slice(bytes);
}

fn event_head(wall_time: f64, step: i64) -> Vec<u8> {
    let mut out = vec![1 << 3 | 1];
    out.extend_from_slice(&wall_time.to_le_bytes());
    varint(2 << 3, &mut out);
    varint(step as u64, &mut out);
    out
}

/// The first event of a file, framed.
pub fn file_version_event(wall_time: f64) -> Vec<u8> {
    let mut e = event_head(wall_time, 0);
    bytes_field(3, FILE_VERSION.as_bytes(), &mut e);
    record(&e)
}

/// One event of the scalars `values` (tag, value) at `step`, framed.
pub fn scalars_event(wall_time: f64, step: u64, values: &[(String, f32)]) -> Vec<u8> {
    let mut summary = Vec::new();
    for (tag, v) in values {
        let mut value = Vec::new();
        bytes_field(1, tag.as_bytes(), &mut value);
        varint(2 << 3 | 5, &mut value);
        value.extend_from_slice(&v.to_le_bytes());
        bytes_field(1, &value, &mut summary);
    }
    let mut e = event_head(wall_time, step as i64);
    bytes_field(5, &summary, &mut e);
    record(&e)
}

/// One scalar as a file holds it.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarEvent {
    pub wall_time: f64,
    pub step: u64,
    pub tag: String,
    pub value: f32,
}

/// A varint at the start of `b`, and the bytes it took.
fn read_varint(b: &[u8]) -> Option<(u64, usize)> {
    let mut v = 0u64;
    for (i, &byte) in b.iter().enumerate().take(10) {
        v |= u64::from(byte & 0x7f) << (7 * i);
        if byte & 0x80 == 0 {
            return Some((v, i + 1));
        }
    }
    None
}

/// One field of a protocol buffer message: its number, its wire type, its bytes (the value of a
/// fixed-width field, the contents of a length-delimited one, empty for a varint) and a varint's
/// value.
type Field<'a> = (u64, u64, &'a [u8], u64);

/// The fields of one protocol buffer message; `None` on one this reader does not understand.
fn fields(mut b: &[u8]) -> Option<Vec<Field<'_>>> {
    let mut out = Vec::new();
    while !b.is_empty() {
        let (key, n) = read_varint(b)?;
        b = &b[n..];
        let (field, wire) = (key >> 3, key & 7);
        match wire {
            0 => {
                let (v, n) = read_varint(b)?;
                out.push((field, wire, &b[..0], v));
                b = &b[n..];
            }
            1 | 5 => {
                let width = if wire == 1 { 8 } else { 4 };
                out.push((field, wire, b.get(..width)?, 0));
                b = &b[width..];
            }
            2 => {
                let (len, n) = read_varint(b)?;
                let end = n + usize::try_from(len).ok()?;
                out.push((field, wire, b.get(n..end)?, 0));
                b = &b[end..];
            }
            _ => return None,
        }
    }
    Some(out)
}

/// The scalars of an event file's bytes, in file order (what [`scalars_event`] writes). A record
/// cut short at the end (one being written) or with a wrong checksum ends the reading.
pub fn read_scalars(mut b: &[u8]) -> Vec<ScalarEvent> {
    let mut out = Vec::new();
    while b.len() >= 12 {
        let len = u64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
        let Ok(len) = usize::try_from(len) else { break };
        if u32::from_le_bytes(b[8..12].try_into().expect("4 bytes")) != masked_crc(&b[..8]) {
            break;
        }
        let Some(data) = b.get(12..12 + len) else {
            break;
        };
        let Some(crc) = b.get(12 + len..16 + len) else {
            break;
        };
        if u32::from_le_bytes(crc.try_into().expect("4 bytes")) != masked_crc(data) {
            break;
        }
        out.extend(event_scalars(data));
        b = &b[16 + len..];
    }
    out
}

/// The scalars of one `Event`'s bytes.
fn event_scalars(data: &[u8]) -> Vec<ScalarEvent> {
    let Some(event) = fields(data) else {
        return Vec::new();
    };
    let (mut wall_time, mut step, mut out) = (0.0, 0, Vec::new());
    for &(field, _, bytes, v) in &event {
        match field {
            1 => wall_time = f64::from_le_bytes(bytes.try_into().unwrap_or([0; 8])),
            2 => step = v,
            _ => {}
        }
    }
    for &(field, _, summary, _) in &event {
        if field != 5 {
            continue;
        }
        for (_, _, value, _) in fields(summary).unwrap_or_default() {
            let (mut tag, mut number) = (None, None);
            for &(f, _, bytes, _) in &fields(value).unwrap_or_default() {
                match f {
                    1 => tag = std::str::from_utf8(bytes).ok().map(str::to_owned),
                    2 => number = bytes.try_into().ok().map(f32::from_le_bytes),
                    _ => {}
                }
            }
            if let (Some(tag), Some(value)) = (tag, number) {
                out.push(ScalarEvent {
                    wall_time,
                    step,
                    tag,
                    value,
                });
            }
        }
    }
    out
}

/// The scalars of a run's episodes, one episode at a time, in the order they end.
#[derive(Debug, Clone)]
pub struct EpisodeScalars {
    budget: u32,
    returns: VecDeque<f64>,
    lengths: VecDeque<f64>,
    /// Each actor's environment steps so far.
    actor_steps: BTreeMap<u16, u64>,
}

impl EpisodeScalars {
    /// For a run whose budget is `budget` demonstrations.
    pub fn new(budget: u32) -> Self {
        Self {
            budget,
            returns: VecDeque::with_capacity(ROLLING),
            lengths: VecDeque::with_capacity(ROLLING),
            actor_steps: BTreeMap::new(),
        }
    }

    /// The scalars after episode `r`, `elapsed_s` seconds into the run (rates need it > 0).
    pub fn after(&mut self, r: &EpisodeRecord, elapsed_s: f64) -> Vec<(String, f32)> {
        if self.returns.len() == ROLLING {
            self.returns.pop_front();
            self.lengths.pop_front();
        }
        self.returns.push_back(r.ret);
        self.lengths.push_back(f64::from(r.length));
        let steps = self.actor_steps.entry(r.actor).or_default();
        *steps += u64::from(r.length);
        let actor_steps = *steps;
        let mean = |v: &VecDeque<f64>| v.iter().sum::<f64>() / v.len() as f64;
        let mut out = vec![
            ("rollout/ep_rew_mean".to_owned(), mean(&self.returns)),
            ("rollout/ep_len_mean".to_owned(), mean(&self.lengths)),
            ("query/js".to_owned(), r.mean_js),
            ("query/gate_fired".to_owned(), f64::from(r.queries)),
            ("demos/used".to_owned(), f64::from(r.demos_used)),
            (
                "demos/budget_left".to_owned(),
                f64::from(self.budget.saturating_sub(r.demos_used)),
            ),
        ];
        if !r.eval_return.is_nan() {
            out.push(("eval/mean_reward".to_owned(), r.eval_return));
        }
        if elapsed_s > 0.0 {
            out.push(("time/fps".to_owned(), r.total_steps as f64 / elapsed_s));
            out.push((
                format!("actor/{}/sps", r.actor),
                actor_steps as f64 / elapsed_s,
            ));
        }
        out.into_iter().map(|(t, v)| (t, v as f32)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_has_the_castagnoli_check_value() {
        // The check value of CRC-32C (RFC 3720, appendix B.4; "123456789").
        assert_eq!(crc32c(b"123456789"), 0xE306_9283);
        assert_eq!(crc32c(b""), 0);
        // 32 bytes of zeros, RFC 3720's first test vector.
        assert_eq!(crc32c(&[0u8; 32]), 0x8A91_36AA);
    }

    #[test]
    fn a_record_frames_its_data_with_length_and_both_checksums() {
        let r = record(b"abc");
        assert_eq!(r.len(), 8 + 4 + 3 + 4);
        assert_eq!(&r[..8], &3u64.to_le_bytes());
        assert_eq!(&r[8..12], &masked_crc(&3u64.to_le_bytes()).to_le_bytes());
        assert_eq!(&r[12..15], b"abc");
        assert_eq!(&r[15..], &masked_crc(b"abc").to_le_bytes());
    }

    #[test]
    fn a_scalar_event_encodes_its_fields_by_hand() {
        let r = scalars_event(1.5, 300, &[("a/b".to_owned(), 2.0)]);
        let data = &r[12..r.len() - 4];
        let mut want = vec![0x09];
        want.extend_from_slice(&1.5f64.to_le_bytes());
        // step 300 = 0xAC 0x02 as a varint.
        want.extend_from_slice(&[0x10, 0xAC, 0x02]);
        // Summary (field 5) { Value (field 1) { tag "a/b", simple_value 2.0 } }.
        want.extend_from_slice(&[0x2A, 12, 0x0A, 10, 0x0A, 3, b'a', b'/', b'b', 0x15]);
        want.extend_from_slice(&2.0f32.to_le_bytes());
        assert_eq!(data, &want[..]);
    }

    #[test]
    fn what_is_written_reads_back_and_a_cut_record_ends_the_reading() {
        let mut file = file_version_event(1.0);
        file.extend(scalars_event(
            2.5,
            300,
            &[("a".into(), 1.5), ("b/c".into(), -2.0)],
        ));
        file.extend(scalars_event(3.5, 301, &[("a".into(), 4.0)]));
        let read = read_scalars(&file);
        let got: Vec<(f64, u64, &str, f32)> = read
            .iter()
            .map(|e| (e.wall_time, e.step, e.tag.as_str(), e.value))
            .collect();
        assert_eq!(
            got,
            [
                (2.5, 300, "a", 1.5),
                (2.5, 300, "b/c", -2.0),
                (3.5, 301, "a", 4.0)
            ]
        );
        assert_eq!(
            read_scalars(&file[..file.len() - 3]).len(),
            2,
            "the last record cut"
        );
        let mut bad = file.clone();
        let at = bad.len() - 6;
        bad[at] ^= 1;
        assert_eq!(read_scalars(&bad).len(), 2, "a wrong checksum ends it");
    }

    #[test]
    fn episode_scalars_keep_rolling_means_rates_and_the_budget_left() {
        let mut s = EpisodeScalars::new(10);
        let ep = |ret: f64, length: u32, total_steps: u64, actor: u16| EpisodeRecord {
            ret,
            length,
            total_steps,
            actor,
            demos_used: 4,
            queries: 2,
            ..EpisodeRecord::default()
        };
        let first = s.after(&ep(1.0, 10, 10, 0), 0.0);
        let get = |v: &[(String, f32)], tag: &str| v.iter().find(|(t, _)| t == tag).map(|p| p.1);
        assert_eq!(get(&first, "rollout/ep_rew_mean"), Some(1.0));
        assert_eq!(get(&first, "demos/budget_left"), Some(6.0));
        assert_eq!(get(&first, "time/fps"), None, "no rate at time 0");
        assert_eq!(get(&first, "eval/mean_reward"), None, "no evaluation");
        let mut e = ep(3.0, 30, 40, 1);
        e.eval_return = 7.0;
        let second = s.after(&e, 2.0);
        assert_eq!(get(&second, "rollout/ep_rew_mean"), Some(2.0));
        assert_eq!(get(&second, "rollout/ep_len_mean"), Some(20.0));
        assert_eq!(get(&second, "eval/mean_reward"), Some(7.0));
        assert_eq!(get(&second, "time/fps"), Some(20.0));
        assert_eq!(get(&second, "actor/1/sps"), Some(15.0));
        for i in 0..ROLLING {
            s.after(&ep(i as f64, 1, 50 + i as u64, 0), 1.0);
        }
        let last = s.after(&ep(100.0, 1, 200, 0), 1.0);
        // The last 100 returns: 1..=100.
        assert_eq!(get(&last, "rollout/ep_rew_mean"), Some(50.5));
    }
}

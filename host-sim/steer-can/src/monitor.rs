//! Live decode of the bus: counts per frame kind, CRC and length errors, alive-counter gaps of
//! the ECU's frames, the last value of everything and the ECU's own diagnostics (0x103: drop
//! counters per reason, bus-offs, every fault record with its age, the oldest unacknowledged
//! first), as a block of text for the terminal.

use super::Stamped;
use super::decode::{
    Decoded, Decoder, as_state_words, ecu_state_words, fault_detail_words, fault_words,
    faults_in_words, frame_error_words, nmt_words,
};
use std::collections::BTreeMap;
use steering_ecu::canopen::nmt::NmtState;
use steering_ecu::faults::FAULT_LOG_CAPACITY;
use steering_ecu::faults::Fault;
use steering_ecu::protocol::{
    AliveCounter, COUNTER_PAGES, Diagnostic, DiagnosticPage, DiagnosticRecord, FrameError,
    MotorStatus, Reference, Status,
};

/// The names of the diagnostic frame's counters, page by page (pages 0..=5, three each), as
/// `Ecu::diagnostic_frame` fills them and the DBC names them.
pub const DIAGNOSTIC_COUNTERS: [[&str; 3]; COUNTER_PAGES as usize] = [
    [
        "dropped: wrong length",
        "dropped: CRC",
        "dropped: stale counter",
    ],
    [
        "dropped: counter jump",
        "dropped: unknown AS state",
        "dropped: angle out of range",
    ],
    ["dropped: rate too high", "early frames", "bus-off events"],
    [
        "refused clear requests",
        "hold entries",
        "lost drive-demand frames",
    ],
    [
        "fault records held",
        "unacknowledged records",
        "records dropped",
    ],
    [
        "stack peak, 4-byte words",
        "stack size, 4-byte words",
        "reserved",
    ],
];

/// One slot of the ECU's fault log as its diagnostic page last came.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordPage {
    /// The slot's page has not come yet.
    NotSeen,
    /// The ECU has fewer records than this slot.
    Empty,
    /// The fault (`Err`: a bit no fault has), its detail, whether a clear acknowledged it,
    /// and its age when the page was sent, s.
    Fault {
        fault: Result<Fault, u8>,
        detail: i32,
        acknowledged: bool,
        age_s: u16,
    },
}

/// The newest page of each counter page and record slot the ECU's diagnostic frame has sent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Diagnostics {
    counters: [Option<[u16; 3]>; COUNTER_PAGES as usize],
    records: [Option<Option<DiagnosticRecord>>; FAULT_LOG_CAPACITY],
    /// Pages with a code the layout does not define.
    pub unknown_pages: u64,
}

impl Diagnostics {
    /// Keeps a page.
    pub fn on(&mut self, d: Diagnostic) {
        match d.page {
            DiagnosticPage::Counters { page, words } => {
                if let Some(slot) = self.counters.get_mut(usize::from(page)) {
                    *slot = Some(words);
                }
            }
            DiagnosticPage::Record { slot, record } => {
                if let Some(s) = self.records.get_mut(usize::from(slot)) {
                    *s = Some(record);
                }
            }
            DiagnosticPage::Unknown { .. } => self.unknown_pages += 1,
        }
    }

    /// A counter by its name in [`DIAGNOSTIC_COUNTERS`]; `None` until its page has come.
    pub fn counter(&self, name: &str) -> Option<u16> {
        DIAGNOSTIC_COUNTERS
            .iter()
            .enumerate()
            .find_map(|(page, names)| {
                let i = names.iter().position(|n| *n == name)?;
                self.counters.get(page)?.as_ref()?.get(i).copied()
            })
    }

    /// The fault log's slots as received, oldest first.
    pub fn records(&self) -> Vec<RecordPage> {
        self.records
            .iter()
            .map(|p| match p {
                None => RecordPage::NotSeen,
                Some(None) => RecordPage::Empty,
                Some(Some(r)) => RecordPage::Fault {
                    fault: Fault::from_bit(r.fault_bit).ok_or(r.fault_bit),
                    detail: r.detail,
                    acknowledged: r.acknowledged,
                    age_s: r.age_s,
                },
            })
            .collect()
    }

    /// The slots holding a record, in the order the summary lists them: the unacknowledged
    /// ones first, oldest first (the first is the root cause still latched), then the
    /// acknowledged ones, oldest first. Each with its slot number.
    pub fn records_by_urgency(&self) -> Vec<(usize, RecordPage)> {
        let held: Vec<(usize, RecordPage)> = self
            .records()
            .into_iter()
            .enumerate()
            .filter(|(_, r)| matches!(r, RecordPage::Fault { .. }))
            .collect();
        let acknowledged = |r: &RecordPage| {
            matches!(
                r,
                RecordPage::Fault {
                    acknowledged: true,
                    ..
                }
            )
        };
        let (done, open): (Vec<_>, Vec<_>) = held.into_iter().partition(|(_, r)| acknowledged(r));
        open.into_iter().chain(done).collect()
    }

    /// The block of text `summary` shows; empty if no page came.
    pub fn summary(&self) -> String {
        if self.counters.iter().all(Option::is_none) && self.records.iter().all(Option::is_none) {
            return String::new();
        }
        let mut out = String::from("  diagnostics (0x103):\n");
        for (page, names) in DIAGNOSTIC_COUNTERS.iter().enumerate() {
            let words = self.counters.get(page).copied().flatten();
            let line: Vec<String> = names
                .iter()
                .enumerate()
                .map(|(i, name)| match words.and_then(|w| w.get(i).copied()) {
                    Some(n) => format!("{name} {n}"),
                    None => format!("{name} (not seen yet)"),
                })
                .collect();
            out.push_str(&format!("    {}\n", line.join(", ")));
        }
        match (
            self.counter("stack peak, 4-byte words"),
            self.counter("stack size, 4-byte words"),
        ) {
            (Some(0), Some(0)) => out.push_str("    stack high-water: not measured\n"),
            (Some(peak), Some(size)) => out.push_str(&format!(
                "    stack high-water: {} B of {} B ({:.1} %)\n",
                4 * u32::from(peak),
                4 * u32::from(size),
                100.0 * f64::from(peak) / f64::from(size.max(1))
            )),
            _ => {}
        }
        let unseen = self.records.iter().filter(|r| r.is_none()).count();
        if unseen > 0 {
            out.push_str(&format!(
                "    fault log: {unseen} of {FAULT_LOG_CAPACITY} slots not seen yet\n"
            ));
        }
        for (slot, record) in self.records_by_urgency() {
            let RecordPage::Fault {
                fault,
                detail,
                acknowledged,
                age_s,
            } = record
            else {
                continue;
            };
            let text = match fault {
                Ok(fault) => format!(
                    "{}: {}",
                    fault_words(fault),
                    fault_detail_words(fault, detail)
                ),
                Err(bit) => format!("unknown fault bit {bit}: detail {detail}"),
            };
            let state = if acknowledged {
                "acknowledged"
            } else {
                "unacknowledged"
            };
            let age = if age_s >= steering_ecu::protocol::RECORD_AGE_MAX_S {
                format!("{age_s} s or more ago")
            } else {
                format!("{age_s} s ago")
            };
            out.push_str(&format!(
                "    fault record {} ({state}, {age}): {text}\n",
                slot + 1
            ));
        }
        if self.unknown_pages > 0 {
            out.push_str(&format!(
                "    pages of an unknown layout: {}\n",
                self.unknown_pages
            ));
        }
        out
    }
}

/// Alive-counter bookkeeping of one frame stream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CounterCheck {
    last: Option<u8>,
    /// Frames whose counter repeated the previous one.
    pub repeats: u64,
    /// Frames missing according to the counter (sum of the jumps).
    pub lost: u64,
}

impl CounterCheck {
    pub fn on(&mut self, counter: AliveCounter) {
        let c = counter.raw();
        if let Some(last) = self.last {
            let step = (c + AliveCounter::MODULUS - last) % AliveCounter::MODULUS;
            match step {
                0 => self.repeats += 1,
                1 => {}
                n => self.lost += u64::from(n - 1),
            }
        }
        self.last = Some(c);
    }
}

/// Everything seen so far.
#[derive(Debug, Clone)]
pub struct Monitor {
    decoder: Decoder,
    pub counts: BTreeMap<&'static str, u64>,
    /// Frames of the ECU's protocol that failed the CRC, per kind.
    pub crc_errors: BTreeMap<&'static str, u64>,
    /// Other check failures (length, AS state code), per kind.
    pub other_errors: BTreeMap<&'static str, u64>,
    pub reference_counter: CounterCheck,
    pub status_counter: CounterCheck,
    pub motor_counter: CounterCheck,
    pub diagnostic_counter: CounterCheck,
    /// The newest page of each number of the ECU's diagnostic frame.
    pub diagnostics: Diagnostics,
    pub last_reference: Option<(u64, Reference)>,
    pub last_status: Option<(u64, Status)>,
    pub last_motor: Option<(u64, MotorStatus)>,
    pub last_tpdo1: Option<(u64, u16, f64)>,
    pub last_tpdo2: Option<(u64, f64)>,
    pub last_heartbeat: Option<(u64, NmtState)>,
    /// Every EMCY: (time, error code, error register).
    pub emcy: Vec<(u64, u16, u8)>,
    /// Fault bits seen set in any status frame.
    pub faults_seen: u16,
    pub first_us: Option<u64>,
    pub last_us: u64,
}

impl Monitor {
    pub fn new(decoder: Decoder) -> Self {
        Monitor {
            decoder,
            counts: BTreeMap::new(),
            crc_errors: BTreeMap::new(),
            other_errors: BTreeMap::new(),
            reference_counter: CounterCheck::default(),
            status_counter: CounterCheck::default(),
            motor_counter: CounterCheck::default(),
            diagnostic_counter: CounterCheck::default(),
            diagnostics: Diagnostics::default(),
            last_reference: None,
            last_status: None,
            last_motor: None,
            last_tpdo1: None,
            last_tpdo2: None,
            last_heartbeat: None,
            emcy: Vec::new(),
            faults_seen: 0,
            first_us: None,
            last_us: 0,
        }
    }

    pub fn decoder(&self) -> &Decoder {
        &self.decoder
    }

    /// Takes one frame; returns what it was.
    pub fn on_frame(&mut self, rx: &Stamped) -> Decoded {
        let t = rx.t_us;
        self.first_us.get_or_insert(t);
        self.last_us = t;
        let d = self.decoder.decode(&rx.frame);
        *self.counts.entry(d.kind()).or_default() += 1;
        let mut error = |e: &FrameError, kind: &'static str| {
            let map = if matches!(e, FrameError::Crc { .. }) {
                &mut self.crc_errors
            } else {
                &mut self.other_errors
            };
            *map.entry(kind).or_default() += 1;
        };
        match &d {
            Decoded::Reference(Ok(r)) => {
                self.reference_counter.on(r.counter);
                self.last_reference = Some((t, *r));
            }
            Decoded::Status(Ok(s)) => {
                self.status_counter.on(s.counter);
                self.faults_seen |= s.faults;
                self.last_status = Some((t, *s));
            }
            Decoded::Motor(Ok(m)) => {
                self.motor_counter.on(m.counter);
                self.last_motor = Some((t, *m));
            }
            Decoded::Diagnostic(Ok(p)) => {
                self.diagnostic_counter.on(p.counter);
                self.diagnostics.on(*p);
            }
            Decoded::Reference(Err(e))
            | Decoded::Status(Err(e))
            | Decoded::Motor(Err(e))
            | Decoded::Diagnostic(Err(e)) => error(e, d.kind()),
            Decoded::EposTpdo1 {
                statusword,
                motor_rad,
            } => self.last_tpdo1 = Some((t, *statusword, *motor_rad)),
            Decoded::EposTpdo2 { current_a } => self.last_tpdo2 = Some((t, *current_a)),
            Decoded::Emcy {
                error_code,
                error_register,
            } => self.emcy.push((t, *error_code, *error_register)),
            Decoded::Heartbeat(s) => self.last_heartbeat = Some((t, *s)),
            _ => {}
        }
        d
    }

    /// One line for a decoded frame (the `--each` view).
    pub fn line(&self, rx: &Stamped, d: &Decoded) -> String {
        let t = rx.t_us as f64 * 1e-6;
        let body = match d {
            Decoded::Reference(Ok(r)) => format!(
                "angle {:+8.2} deg  AS {}  counter {:2}{}",
                r.angle.0,
                as_state_words(r.as_state),
                r.counter.raw(),
                if r.clear_faults { "  clear-faults" } else { "" }
            ),
            Decoded::Status(Ok(s)) => format!(
                "column {:+8.2} deg  current {:+7.2} A  state {}  faults: {}  counter {:2}",
                s.angle.0,
                s.current.0,
                ecu_state_words(s.ecu_state),
                faults_in_words(s.faults),
                s.counter.raw()
            ),
            Decoded::Motor(Ok(m)) => format!(
                "motor {:+10.4} rad  mean current {:+7.3} A  counter {:2}  ECU's reference \
                 counter {:2}",
                m.angle.0,
                m.current_mean.0,
                m.counter.raw(),
                m.reference_counter.raw()
            ),
            Decoded::Diagnostic(Ok(p)) => diagnostic_line(p),
            Decoded::Reference(Err(e))
            | Decoded::Status(Err(e))
            | Decoded::Motor(Err(e))
            | Decoded::Diagnostic(Err(e)) => frame_error_words(e),
            Decoded::EposTpdo1 {
                statusword,
                motor_rad,
            } => format!("statusword 0x{statusword:04X}  position {motor_rad:+10.4} rad"),
            Decoded::EposTpdo2 { current_a } => format!("current {current_a:+7.3} A"),
            Decoded::EposRpdo1 { target_rad } => format!("target {target_rad:+10.4} rad"),
            Decoded::EposPdoLength { cob, len } => format!("COB 0x{cob:03X} length {len}"),
            Decoded::Emcy {
                error_code,
                error_register,
            } => format!("error code 0x{error_code:04X}  error register 0x{error_register:02X}"),
            Decoded::Heartbeat(s) | Decoded::EcuHeartbeat(s) => nmt_words(*s).to_string(),
            _ => hex(rx.frame.data()),
        };
        format!(
            "{t:12.6}  {:03X}  {:<18} {body}",
            rx.frame.id().raw(),
            d.kind()
        )
    }

    /// The summary block: rates, errors, last values.
    pub fn summary(&self) -> String {
        let span_s = self
            .first_us
            .map(|f| (self.last_us.saturating_sub(f)) as f64 * 1e-6)
            .unwrap_or(0.0);
        let mut out = String::new();
        out.push_str(&format!(
            "{:.1} s of bus, {} frames\n",
            span_s,
            self.counts.values().sum::<u64>()
        ));
        for (kind, n) in &self.counts {
            let rate = if span_s > 0.0 {
                *n as f64 / span_s
            } else {
                0.0
            };
            let crc = self.crc_errors.get(kind).copied().unwrap_or(0);
            let other = self.other_errors.get(kind).copied().unwrap_or(0);
            out.push_str(&format!(
                "  {kind:<22} {n:7}  {rate:7.1} Hz  CRC errors {crc}  other errors {other}\n"
            ));
        }
        for (name, c) in [
            ("reference", &self.reference_counter),
            ("status", &self.status_counter),
            ("motor", &self.motor_counter),
            ("diagnostics", &self.diagnostic_counter),
        ] {
            if c.last.is_some() {
                out.push_str(&format!(
                    "  {name} counter: {} lost, {} repeated\n",
                    c.lost, c.repeats
                ));
            }
        }
        if let Some((_, r)) = &self.last_reference {
            out.push_str(&format!(
                "  reference  {:+8.2} deg, AS {}\n",
                r.angle.0,
                as_state_words(r.as_state)
            ));
        }
        match &self.last_status {
            Some((_, s)) => out.push_str(&format!(
                "  ECU        column {:+8.2} deg, current {:+7.2} A, state {}, faults: {}\n",
                s.angle.0,
                s.current.0,
                ecu_state_words(s.ecu_state),
                faults_in_words(s.faults)
            )),
            None => out.push_str("  ECU        no status frame (0x101) yet\n"),
        }
        if let Some((_, m)) = &self.last_motor {
            out.push_str(&format!(
                "  motor      {:+10.4} rad, mean current {:+7.3} A, last reference counter {}\n",
                m.angle.0,
                m.current_mean.0,
                m.reference_counter.raw()
            ));
        }
        if let Some((_, s)) = &self.last_heartbeat {
            out.push_str(&format!("  EPOS4      NMT {}\n", nmt_words(*s)));
        }
        if let Some((_, sw, rad)) = &self.last_tpdo1 {
            out.push_str(&format!(
                "  EPOS4      statusword 0x{sw:04X}, position {rad:+10.4} rad\n"
            ));
        }
        if let Some((_, a)) = &self.last_tpdo2 {
            out.push_str(&format!("  EPOS4      current {a:+7.3} A\n"));
        }
        for (t, code, reg) in &self.emcy {
            out.push_str(&format!(
                "  EMCY at {:.3} s: error code 0x{code:04X}, error register 0x{reg:02X}\n",
                *t as f64 * 1e-6
            ));
        }
        if self.faults_seen != 0 {
            out.push_str(&format!(
                "  faults seen: {}\n",
                faults_in_words(self.faults_seen)
            ));
        }
        out.push_str(&self.diagnostics.summary());
        out
    }
}

/// One diagnostic page in words (the `--each` view).
fn diagnostic_line(p: &Diagnostic) -> String {
    let body = match p.page {
        DiagnosticPage::Counters { page, words } => {
            match DIAGNOSTIC_COUNTERS.get(usize::from(page)) {
                Some(names) => names
                    .iter()
                    .zip(words)
                    .map(|(name, n)| format!("{name} {n}"))
                    .collect::<Vec<_>>()
                    .join(", "),
                None => format!("counters {words:?}"),
            }
        }
        DiagnosticPage::Record { slot, record } => {
            let text = match record {
                None => "empty".into(),
                Some(r) => {
                    let what = match Fault::from_bit(r.fault_bit) {
                        Some(f) => {
                            format!("{}: {}", fault_words(f), fault_detail_words(f, r.detail))
                        }
                        None => format!("unknown fault bit {}: detail {}", r.fault_bit, r.detail),
                    };
                    let state = if r.acknowledged {
                        "acknowledged"
                    } else {
                        "unacknowledged"
                    };
                    format!("{what} ({state}, {} s ago)", r.age_s)
                }
            };
            format!("fault record {}: {text}", usize::from(slot) + 1)
        }
        DiagnosticPage::Unknown { payload, .. } => {
            format!("unknown page layout, payload 0x{payload:012X}")
        }
    };
    format!(
        "page {}  {body}  counter {:2}",
        p.page.code(),
        p.counter.raw()
    )
}

fn hex(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(slot: u8, fault: Fault, acknowledged: bool, age_s: u16) -> Diagnostic {
        Diagnostic {
            counter: AliveCounter::wrapping(0),
            page: DiagnosticPage::Record {
                slot,
                record: Some(DiagnosticRecord {
                    fault_bit: fault.bit(),
                    acknowledged,
                    detail: 200,
                    age_s,
                }),
            },
        }
    }

    /// The summary lists the oldest unacknowledged record first (the root cause still
    /// latched), then the newer unacknowledged ones, then the acknowledged ones.
    #[test]
    fn the_oldest_unacknowledged_fault_comes_first() {
        let mut d = Diagnostics::default();
        d.on(record(0, Fault::EposFault, true, 90));
        d.on(record(1, Fault::BusOff, false, 40));
        d.on(record(2, Fault::HeartbeatLost, false, 39));
        for slot in 3..FAULT_LOG_CAPACITY as u8 {
            d.on(Diagnostic {
                counter: AliveCounter::wrapping(0),
                page: DiagnosticPage::Record { slot, record: None },
            });
        }
        d.on(Diagnostic {
            counter: AliveCounter::wrapping(0),
            page: DiagnosticPage::Counters {
                page: 5,
                words: [1234, 31_644, 0],
            },
        });
        assert!(
            d.summary()
                .contains("stack high-water: 4936 B of 126576 B (3.9 %)"),
            "{}",
            d.summary()
        );
        let order: Vec<usize> = d.records_by_urgency().iter().map(|(s, _)| *s).collect();
        assert_eq!(order, [1, 2, 0]);
        let text = d.summary();
        let bus_off = text.find("fault record 2 (unacknowledged, 40 s ago): CAN bus-off");
        let heartbeat = text.find("fault record 3 (unacknowledged, 39 s ago)");
        let epos = text.find("fault record 1 (acknowledged, 90 s ago)");
        assert!(
            bus_off.is_some() && bus_off < heartbeat && heartbeat < epos,
            "{text}"
        );
    }

    /// The motor frame's reference counter (the one a new sender continues) is shown in the
    /// `--each` line and in the summary.
    #[test]
    fn the_ecus_reference_counter_is_shown() {
        use steering_ecu::canopen::NodeId;
        use steering_ecu::canopen::epos4::PositionScale;
        use steering_ecu::protocol::ProtocolConfig;
        use steering_ecu::units::{Amps, MotorRad};
        let dec = Decoder::new(NodeId::new(1).unwrap(), PositionScale::new(4096).unwrap());
        let mut m = Monitor::new(dec);
        let rx = Stamped {
            t_us: 0,
            frame: ProtocolConfig::DEFAULT.encode_motor(&MotorStatus {
                angle: MotorRad(1.0),
                current_mean: Amps(0.5),
                counter: AliveCounter::wrapping(3),
                reference_counter: AliveCounter::wrapping(11),
            }),
        };
        let d = m.on_frame(&rx);
        assert!(m.line(&rx, &d).ends_with("ECU's reference counter 11"));
        assert!(
            m.summary().contains(", last reference counter 11\n"),
            "{}",
            m.summary()
        );
    }

    #[test]
    fn counter_gaps_and_repeats_are_counted() {
        let mut c = CounterCheck::default();
        for raw in [14u8, 15, 0, 0, 3, 4] {
            c.on(AliveCounter::wrapping(raw));
        }
        assert_eq!(c.repeats, 1);
        assert_eq!(c.lost, 2);
    }
}

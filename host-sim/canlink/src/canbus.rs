//! An in-memory classic CAN bus for host tests: several nodes, broadcast delivery in send
//! order, and faults on purpose — drop, delay and bit flips — from a seeded RNG or from an
//! explicit schedule, so every run is reproducible.
//!
//! Time is the caller's `now_us`. A frame sent at `t` is delivered at `t + latency_us` (plus
//! any injected delay) to every node except the sender, in (delivery time, send order).
//! A corrupted frame is still delivered, with one bit of its identifier or data flipped: a real
//! controller would drop it on the CRC, but delivering it exercises the decoders' handling of
//! arbitrary frames, which is the point of a stricter fake.

use det_rng::XorShift64Star;
use std::collections::BTreeMap;
use steering_ecu::can::{Frame, StandardId};

/// A node's handle on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Port(usize);

/// What happens to one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    Drop,
    /// Delivered this many µs late (frames sent later may overtake it).
    Delay {
        us: u64,
    },
    /// Flip bit `bit` of the frame: 0..=10 are the identifier, 11.. the data bytes
    /// (bit 11 = `data[0]` bit 0); out-of-range bits wrap over the frame's bits.
    FlipBit {
        bit: u32,
    },
}

/// Random faults, each drawn independently per frame (probabilities in 0..=1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RandomFaults {
    pub drop: f64,
    pub corrupt: f64,
    pub delay: f64,
    pub max_delay_us: u64,
}

/// Counters of what the bus did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusStats {
    pub sent: u64,
    pub dropped: u64,
    pub corrupted: u64,
    pub delayed: u64,
    pub delivered: u64,
}

#[derive(Debug, Clone)]
struct InFlight {
    from: Port,
    frame: Frame,
}

/// The bus.
#[derive(Debug, Clone)]
pub struct CanBus {
    ports: usize,
    latency_us: u64,
    rng: XorShift64Star,
    random: RandomFaults,
    /// Faults for the n-th frame sent (0-based), applied before random faults.
    schedule: BTreeMap<u64, Fault>,
    /// Ports whose frames are all dropped (a node cut off / powered down).
    silenced: Vec<bool>,
    /// (delivery time, send sequence) -> frame
    queue: BTreeMap<(u64, u64), InFlight>,
    stats: BusStats,
}

impl CanBus {
    /// A fault-free bus with `latency_us` per frame (about 0.13 ms for 8 bytes at 1 Mbit/s).
    pub fn new(seed: u64, latency_us: u64) -> Self {
        CanBus {
            ports: 0,
            latency_us,
            rng: XorShift64Star::seeded(seed),
            random: RandomFaults::default(),
            schedule: BTreeMap::new(),
            silenced: Vec::new(),
            queue: BTreeMap::new(),
            stats: BusStats::default(),
        }
    }

    pub fn attach(&mut self) -> Port {
        self.ports += 1;
        self.silenced.push(false);
        Port(self.ports - 1)
    }

    pub fn set_random_faults(&mut self, faults: RandomFaults) {
        self.random = faults;
    }

    /// Apply `fault` to the `nth` frame sent from now on counting from bus creation (0-based).
    pub fn schedule(&mut self, nth: u64, fault: Fault) {
        self.schedule.insert(nth, fault);
    }

    /// Drop (or stop dropping) everything `port` sends.
    pub fn silence(&mut self, port: Port, silenced: bool) {
        if let Some(s) = self.silenced.get_mut(port.0) {
            *s = silenced;
        }
    }

    pub fn stats(&self) -> BusStats {
        self.stats
    }

    pub fn send(&mut self, from: Port, frame: Frame, now_us: u64) {
        let seq = self.stats.sent;
        self.stats.sent += 1;
        if self.silenced.get(from.0).copied().unwrap_or(true) {
            self.stats.dropped += 1;
            return;
        }
        let mut frame = frame;
        let mut delay = 0;
        let scheduled = self.schedule.remove(&seq);
        let faults: Vec<Fault> = match scheduled {
            Some(f) => vec![f],
            None => self.draw_random(),
        };
        for fault in faults {
            match fault {
                Fault::Drop => {
                    self.stats.dropped += 1;
                    return;
                }
                Fault::Delay { us } => {
                    self.stats.delayed += 1;
                    delay += us;
                }
                Fault::FlipBit { bit } => {
                    self.stats.corrupted += 1;
                    frame = flip(&frame, bit);
                }
            }
        }
        let at = now_us + self.latency_us + delay;
        self.queue.insert((at, seq), InFlight { from, frame });
    }

    fn draw_random(&mut self) -> Vec<Fault> {
        let r = self.random;
        let mut faults = Vec::new();
        // Always draw the same number of values per frame so one probability does not shift
        // the sequence of the others.
        let (d, c, l, bit, us) = (
            self.rng.unit(),
            self.rng.unit(),
            self.rng.unit(),
            self.rng.next_u64(),
            self.rng.next_u64(),
        );
        if d < r.drop {
            faults.push(Fault::Drop);
        }
        if c < r.corrupt {
            faults.push(Fault::FlipBit {
                bit: (bit % 75) as u32,
            });
        }
        if l < r.delay && r.max_delay_us > 0 {
            faults.push(Fault::Delay {
                us: 1 + us % r.max_delay_us,
            });
        }
        faults
    }

    /// Frames due at `now_us`, each as (receiving port, frame), in delivery order.
    pub fn deliver(&mut self, now_us: u64) -> Vec<(Port, Frame)> {
        let mut out = Vec::new();
        while let Some(entry) = self.queue.first_entry() {
            if entry.key().0 > now_us {
                break;
            }
            let f = entry.remove();
            for p in 0..self.ports {
                if p != f.from.0 {
                    out.push((Port(p), f.frame));
                    self.stats.delivered += 1;
                }
            }
        }
        out
    }

    pub fn in_flight(&self) -> usize {
        self.queue.len()
    }
}

/// `frame` with one bit flipped (identifier bits 0..=10, then the data bits).
pub fn flip(frame: &Frame, bit: u32) -> Frame {
    let data_bits = frame.data().len() as u32 * 8;
    let bit = bit % (11 + data_bits);
    if bit < 11 {
        let id = StandardId::new(frame.id().raw() ^ (1 << bit)).unwrap_or(frame.id());
        Frame::new(id, frame.data()).unwrap_or(*frame)
    } else {
        let b = bit - 11;
        let mut data = [0u8; 8];
        let len = frame.data().len();
        data[..len].copy_from_slice(frame.data());
        data[(b / 8) as usize] ^= 1 << (b % 8);
        Frame::new(frame.id(), &data[..len]).unwrap_or(*frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16, data: &[u8]) -> Frame {
        Frame::new(StandardId::new(id).unwrap(), data).unwrap()
    }

    #[test]
    fn delivers_to_every_other_node_in_send_order_after_the_latency() {
        let mut bus = CanBus::new(1, 100);
        let a = bus.attach();
        let b = bus.attach();
        let c = bus.attach();
        bus.send(a, frame(0x10, &[1]), 0);
        bus.send(b, frame(0x11, &[2]), 0);
        assert!(bus.deliver(99).is_empty());
        let got = bus.deliver(100);
        assert_eq!(
            got,
            vec![
                (b, frame(0x10, &[1])),
                (c, frame(0x10, &[1])),
                (a, frame(0x11, &[2])),
                (c, frame(0x11, &[2])),
            ]
        );
        assert_eq!(bus.in_flight(), 0);
    }

    #[test]
    fn scheduled_drop_delay_and_flip_hit_the_named_frames() {
        let mut bus = CanBus::new(1, 0);
        let a = bus.attach();
        let b = bus.attach();
        bus.schedule(0, Fault::Drop);
        bus.schedule(1, Fault::Delay { us: 500 });
        bus.schedule(2, Fault::FlipBit { bit: 11 });
        bus.send(a, frame(0x20, &[0]), 0);
        bus.send(a, frame(0x21, &[0]), 0);
        bus.send(a, frame(0x22, &[0]), 0);
        assert_eq!(bus.deliver(0), vec![(b, frame(0x22, &[1]))]);
        assert_eq!(bus.deliver(500), vec![(b, frame(0x21, &[0]))]);
        let s = bus.stats();
        assert_eq!((s.dropped, s.delayed, s.corrupted), (1, 1, 1));
    }

    #[test]
    fn random_faults_repeat_with_the_seed() {
        let run = |seed| {
            let mut bus = CanBus::new(seed, 10);
            let a = bus.attach();
            bus.attach();
            bus.set_random_faults(RandomFaults {
                drop: 0.2,
                corrupt: 0.2,
                delay: 0.2,
                max_delay_us: 1_000,
            });
            for i in 0..200u16 {
                bus.send(a, frame(i, &[i as u8, 7]), i as u64 * 10);
            }
            (bus.deliver(u64::MAX), bus.stats())
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7).0, run(8).0);
        assert_ne!(run(6).0, run(7).0);
        let (_, s) = run(7);
        assert!(s.dropped > 20 && s.dropped < 70, "{s:?}");
        assert!(s.corrupted > 20 && s.corrupted < 70, "{s:?}");
    }

    #[test]
    fn a_silenced_port_reaches_nobody() {
        let mut bus = CanBus::new(1, 0);
        let a = bus.attach();
        bus.attach();
        bus.silence(a, true);
        bus.send(a, frame(0x700, &[5]), 0);
        assert!(bus.deliver(10).is_empty());
    }

    #[test]
    fn flip_covers_identifier_and_data_bits() {
        let f = frame(0x001, &[0x00, 0x00]);
        assert_eq!(flip(&f, 0).id().raw(), 0x000);
        assert_eq!(flip(&f, 10).id().raw(), 0x401);
        assert_eq!(flip(&f, 26).data(), &[0x00, 0x80]);
        // wraps: 11 id bits + 16 data bits = 27
        assert_eq!(flip(&f, 27), flip(&f, 0));
    }
}

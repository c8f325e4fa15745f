//! The vehicle side's reference frames (0x100): one alive counter for the whole session, the
//! CRC and the AS state the sender claims. The bring-up tool sends them on the car and the
//! simulated vehicle computer in host-sim sends them to the simulated car, so both use this.

use steering_ecu::as_state::AsState;
use steering_ecu::can::Frame;
use steering_ecu::protocol::{AliveCounter, ProtocolConfig, Reference};
use steering_ecu::units::SteeringDeg;

/// Builds reference frames: one counter for the whole session, so the ECU's E2E check sees
/// +1 per frame whatever the caller sends.
#[derive(Debug, Clone)]
pub struct ReferenceSender {
    protocol: ProtocolConfig,
    counter: AliveCounter,
}

impl Default for ReferenceSender {
    fn default() -> Self {
        ReferenceSender {
            protocol: ProtocolConfig::DEFAULT,
            counter: AliveCounter::wrapping(0),
        }
    }
}

impl ReferenceSender {
    /// Continue after `last`: the next frame carries `last + 1`. A sender that starts while the
    /// ECU runs takes `last` from the ECU's motor frame (`MOT_RefCounter`), so the ECU does not
    /// drop its first frame as a counter jump.
    pub fn continue_after(&mut self, last: AliveCounter) {
        self.counter = last;
    }

    /// The counter of the last frame built (0 before the first).
    pub fn last(&self) -> AliveCounter {
        self.counter
    }

    /// The next frame: `angle_deg` at the wheel, in AS state `as_state`.
    pub fn frame(&mut self, angle_deg: f64, as_state: AsState, clear_faults: bool) -> Frame {
        self.counter = self.counter.next();
        self.protocol.encode_reference(&Reference {
            angle: SteeringDeg(angle_deg as f32),
            as_state,
            counter: self.counter,
            clear_faults,
        })
    }
}

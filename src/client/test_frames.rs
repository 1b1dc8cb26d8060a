//! Frames the tests of the client and of the stream fitting feed in.

use vtol_link::dialect::{self as apm, MavMessage};
use vtol_link::{ComponentId, Frame, SystemId};

/// A SiK radio's RADIO_STATUS (it speaks as system 51, component 68) with `txbuf` percent of
/// its transmit buffer free.
pub(crate) fn radio_status(txbuf: u8, seq: u8) -> Frame {
    let m = MavMessage::RADIO_STATUS(apm::RADIO_STATUS_DATA {
        rxerrors: 0,
        fixed: 0,
        rssi: 200,
        remrssi: 190,
        txbuf,
        noise: 40,
        remnoise: 41,
    });
    Frame::encode_v2(SystemId(51), ComponentId(68), seq, &m)
}

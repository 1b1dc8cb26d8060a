//! MAVLink FTP (`PROTOCOL.md` A.10): the twin has no file system, so every request gets a NAK
//! with `FileNotFound`. MAVProxy's `param_ftp` then falls back to PARAM_REQUEST_LIST at once
//! instead of retrying for about 12 seconds.

use mavlink::dialects::ardupilotmega as apm;

use super::{Endpoint, Frame, LinkKey};

/// FTP opcode of a NAK.
pub const OPCODE_NAK: u8 = 129;
/// FTP error code FileNotFound.
pub const ERR_FILE_NOT_FOUND: u8 = 10;

/// The NAK payload for a request payload (A.10 layout):
/// `seq+1 u16 | session | 129 | size 1 | req_opcode | burst 0 | pad | offset u32 0 | data[0] = 10`.
#[must_use]
pub fn nak_payload(request: &[u8; 251]) -> [u8; 251] {
    let seq = u16::from_le_bytes([request[0], request[1]]).wrapping_add(1);
    let mut out = [0u8; 251];
    out[..2].copy_from_slice(&seq.to_le_bytes());
    out[2] = request[2];
    out[3] = OPCODE_NAK;
    out[4] = 1;
    out[5] = request[3];
    out[12] = ERR_FILE_NOT_FOUND;
    out
}

impl Endpoint {
    pub(super) fn on_ftp(
        &mut self,
        link: LinkKey,
        frame: &Frame,
        f: &apm::FILE_TRANSFER_PROTOCOL_DATA,
    ) {
        // A NAK of our own would come back to us through a loop; never answer one.
        if f.payload[3] == OPCODE_NAK || f.payload[3] == 128 {
            return;
        }
        let reply = apm::MavMessage::FILE_TRANSFER_PROTOCOL(apm::FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: frame.system_id(),
            target_component: frame.component_id(),
            payload: nak_payload(&f.payload),
        });
        self.send(link, &reply);
    }
}

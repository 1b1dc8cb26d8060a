//! The parameter protocol (`PROTOCOL.md` A.3): PARAM_REQUEST_LIST (paced from `tick`),
//! PARAM_REQUEST_READ by name (index −1) or index, PARAM_SET with the echo as acknowledgement,
//! PARAM_ERROR for refusals and unknown names, C-cast encoding, persistence and side effects.

use mavlink::dialects::ardupilotmega as apm;
use mavlink::types::CharArray;
use nalgebra::Vector3;

use super::{Endpoint, Frame, LinkKey, streams};
use crate::model::frames::body_rates_to_frd;
use crate::nav::params::{Access, ParamError, ParamType, Params};

/// PARAM_VALUEs sent per link per tick during a list transfer. The serve loop ticks every 5 ms,
/// so this is about 2000 per second: the whole table in a few ticks without flooding a
/// 57600-baud radio for longer than ArduPilot would.
pub const PARAMS_PER_TICK: usize = 10;

/// PARAM_SET.
const PARAM_SET_ID: u32 = vtol_link::protocol::id::PARAM_SET;

/// PARAM_SET read from the raw payload: the typed decoder refuses `param_type` values outside
/// the enum (pymavlink may send 0), and the contract says to ignore the type anyway. Returns
/// (value, target system, target component, name).
#[must_use]
pub fn raw_param_set(frame: &Frame) -> Option<(f32, u8, u8, String)> {
    if frame.message_id() != PARAM_SET_ID {
        return None;
    }
    // param_value f32, target_system, target_component, param_id char[16], param_type.
    let p: [u8; 23] = frame.payload_padded();
    let value = f32::from_le_bytes([p[0], p[1], p[2], p[3]]);
    Some((value, p[4], p[5], param_id_from(&p[6..22])))
}

/// A `char[16]` parameter id: up to the first NUL, all 16 bytes when full.
#[must_use]
pub fn param_id_from(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// Sent before a parameter list, like ArduPilot's banner.
pub const BANNER: &str = concat!(
    "firmware-sim ",
    env!("CARGO_PKG_VERSION"),
    " two-rotor VTOL twin"
);

fn mav_param_type(ty: ParamType) -> apm::MavParamType {
    use apm::MavParamType as T;
    match ty {
        ParamType::Real32 => T::MAV_PARAM_TYPE_REAL32,
        ParamType::Int8 => T::MAV_PARAM_TYPE_INT8,
        ParamType::Int16 => T::MAV_PARAM_TYPE_INT16,
        ParamType::Int32 => T::MAV_PARAM_TYPE_INT32,
    }
}

fn mav_param_error(code: u8) -> apm::MavParamError {
    use apm::MavParamError as E;
    match code {
        1 => E::MAV_PARAM_ERROR_DOES_NOT_EXIST,
        5 => E::MAV_PARAM_ERROR_READ_ONLY,
        _ => E::MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
    }
}

impl Endpoint {
    /// PARAM_VALUE for the parameter at `index` (C-cast: integers as their float value).
    fn param_value(&self, index: usize) -> Option<apm::MavMessage> {
        let (d, v) = self.params.at(index)?;
        Some(apm::MavMessage::PARAM_VALUE(apm::PARAM_VALUE_DATA {
            param_value: v as f32,
            param_count: self.params.count() as u16,
            param_index: index as u16,
            param_id: CharArray::from(d.name),
            param_type: mav_param_type(d.ty),
        }))
    }

    fn param_error(&mut self, link: LinkKey, frame: &Frame, name: &str, index: i16, code: u8) {
        let msg = apm::MavMessage::PARAM_ERROR(apm::PARAM_ERROR_DATA {
            param_index: index,
            target_system: frame.system_id(),
            target_component: frame.component_id(),
            param_id: CharArray::from(name),
            error: mav_param_error(code),
        });
        self.send(link, &msg);
    }

    pub(super) fn param_request_list(&mut self, link: LinkKey) {
        self.say(link, apm::MavSeverity::MAV_SEVERITY_INFO, BANNER);
        let count = self.params.count() as u16;
        if let Some(l) = self.links.get_mut(&link) {
            // A new request restarts the transfer rather than queueing a second copy.
            l.param_queue = (0..count).collect();
        }
    }

    pub(super) fn drain_param_queues(&mut self) {
        let keys: Vec<LinkKey> = self.links.keys().copied().collect();
        for link in keys {
            for _ in 0..PARAMS_PER_TICK {
                let Some(index) = self
                    .links
                    .get_mut(&link)
                    .and_then(|l| l.param_queue.pop_front())
                else {
                    break;
                };
                if let Some(msg) = self.param_value(usize::from(index)) {
                    self.send(link, &msg);
                }
            }
        }
    }

    pub(super) fn param_request_read(
        &mut self,
        link: LinkKey,
        frame: &Frame,
        r: &apm::PARAM_REQUEST_READ_DATA,
    ) {
        let name = r.param_id.to_str().unwrap_or("").to_owned();
        let index = if r.param_index == -1 {
            Params::index_of(&name)
        } else {
            usize::try_from(r.param_index)
                .ok()
                .filter(|&i| i < self.params.count())
        };
        match index.and_then(|i| self.param_value(i)) {
            Some(msg) => self.send(link, &msg),
            None => self.param_error(link, frame, &name, r.param_index, 1),
        }
    }

    /// PARAM_SET: the stored value is echoed on every link on success (so every GCS's cache
    /// follows), the unchanged value plus PARAM_ERROR and a STATUSTEXT to the requester on
    /// refusal, and only PARAM_ERROR (index −1) for an unknown name.
    pub(super) fn param_set(&mut self, link: LinkKey, frame: &Frame, name: &str, value: f32) {
        match self.set_param(name, f64::from(value)) {
            Ok(index) => {
                if let Some(msg) = self.param_value(index) {
                    self.broadcast(&msg);
                }
            }
            Err(ParamError::Unknown(_)) => self.param_error(link, frame, name, -1, 1),
            Err(e) => {
                let index = Params::index_of(name).unwrap_or(0);
                if let Some(msg) = self.param_value(index) {
                    self.send(link, &msg);
                }
                self.param_error(link, frame, name, index as i16, e.mav_error());
                // ArduPilot's wording; the full reason goes to the log, a short one fits STATUSTEXT.
                tracing::warn!("param write denied: {e}");
                let text = format!("Param write denied ({name}: {})", e.short_reason());
                self.say(link, apm::MavSeverity::MAV_SEVERITY_WARNING, &text);
            }
        }
    }

    /// Writes a parameter as a GCS would, applies its effect on the twin and persists the table.
    ///
    /// # Errors
    /// The refusal reason; nothing changes then.
    pub fn set_param(&mut self, name: &str, value: f64) -> Result<usize, ParamError> {
        let accepted = self.params.set(name, value)?;
        let def = crate::nav::params::TABLE[accepted.index];
        self.apply_param_effect(def.name, accepted.new);
        if def.access == Access::ReadWrite {
            self.persist();
        }
        Ok(accepted.index)
    }

    /// Writes a parameter for the test harness rather than for a GCS: the same checks and
    /// effects as a PARAM_SET, and every GCS gets the PARAM_VALUE of the change (collect it
    /// with [`Endpoint::take_outbound`]). Returns the value stored, after its type conversion.
    ///
    /// # Errors
    /// The refusal reason; nothing changes then.
    pub fn set_param_announced(&mut self, name: &str, value: f64) -> Result<f64, ParamError> {
        let index = self.set_param(name, value)?;
        if let Some(msg) = self.param_value(index) {
            self.broadcast(&msg);
        }
        Ok(self.params.at(index).map_or(value, |(_, v)| v))
    }

    fn persist(&mut self) {
        let Some(path) = self.param_file.clone() else {
            return;
        };
        if let Err(e) = self.params.save(&path) {
            tracing::warn!("saving parameters: {e}");
            self.announce(apm::MavSeverity::MAV_SEVERITY_WARNING, "Param save failed");
        }
    }

    fn apply_param_effect(&mut self, name: &'static str, value: f64) {
        match name {
            n if n.starts_with("LAT_SAT")
                || n.starts_with("LON_SAT")
                || matches!(
                    n,
                    "ALT_KD" | "ALT_KP" | "YAW_KD" | "YAW_KP" | "HOVER_ALT" | "LAND_SPEED"
                ) =>
            {
                // Params::set already validated the whole set, so this cannot fail.
                if let Err(e) = self.vehicle.set_gains(self.params.gains()) {
                    tracing::error!("gains accepted by the table but refused by the vehicle: {e}");
                }
            }
            n if n.starts_with("SR0_") => {
                let hz = (value >= 0.0).then_some(value);
                if let Some(group) = streams::Group::ALL.into_iter().find(|g| g.param() == n) {
                    let now = self.stream_now_us;
                    for l in self.links.values_mut() {
                        l.schedule.set_group(group, hz, now);
                    }
                }
            }
            "SIM_PUSH_ROLL" | "SIM_PUSH_PITCH" | "SIM_PUSH_YAW" if value != 0.0 => {
                let axis = ["SIM_PUSH_ROLL", "SIM_PUSH_PITCH", "SIM_PUSH_YAW"]
                    .iter()
                    .position(|a| *a == name)
                    .unwrap_or(0);
                let mut frd = Vector3::zeros();
                frd[axis] = value;
                // The parameters are in the FRD body frame a GCS shows; the twin's body frame
                // differs by the same sign flips as the rates.
                let torque_body_nm = Vector3::from(body_rates_to_frd(&frd));
                let duration_s = self.params.value("SIM_PUSH_MS") / 1000.0;
                self.vehicle.push(torque_body_nm, duration_s);
                let end = self.now_us + (duration_s * 1e6) as u64;
                self.push_resets.retain(|(n, _)| *n != name);
                self.push_resets.push((name, end));
            }
            "SIM_WIND_SPD" | "SIM_WIND_DIR" | "SIM_WIND_TURB" => self.apply_wind(),
            _ => {}
        }
    }

    /// Wind from `SIM_WIND_*`: the direction is where the wind comes from (ArduPilot SITL).
    pub(super) fn apply_wind(&mut self) {
        let (wind, gust) = self.params.wind_paper_m_s();
        self.vehicle.set_wind(wind, gust);
    }

    /// Resets one-shot push parameters whose push is over, and tells every GCS.
    pub(super) fn expire_pushes(&mut self) {
        let now = self.now_us;
        let (done, keep): (Vec<_>, Vec<_>) =
            self.push_resets.drain(..).partition(|(_, end)| *end <= now);
        self.push_resets = keep;
        for (name, _) in done {
            let reset = self.params.set_internal(name, 0.0).ok();
            if let Some(msg) = reset.and_then(|a| self.param_value(a.index)) {
                self.broadcast(&msg);
            }
        }
    }
}

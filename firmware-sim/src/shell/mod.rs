//! The processes around the vehicle: the MAVLink server and its sockets, fleets, the real-time
//! and lockstep clocks, the test harness, signing state, tlogs and the offline `simulate` runner.

pub mod clock;
pub mod fleet;
pub mod harness;
pub mod radio;
pub mod serve;
pub mod signing;
pub mod sik;
pub mod simulate;
pub mod tlog;
pub(crate) mod vehicle_loop;

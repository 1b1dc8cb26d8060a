//! How far the daemon trusts each endpoint, and its MAVLink 2 signing: shared by the router,
//! which applies them to every frame, and the client, which signs its own traffic, without one
//! reaching into the other.

pub mod policy;
pub mod signing;

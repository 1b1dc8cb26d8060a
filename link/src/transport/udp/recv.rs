//! A reader thread's receive buffers: one `recvfrom` per wake-up, or one `recvmmsg` in bursts.

use std::io::{self, IoSliceMut};
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::{Duration, Instant};

use super::{MAX_DATAGRAM_BYTES, RECV_BATCH};
use nix::sys::socket::{MsgFlags, MultiHeaders, SockaddrStorage, recvmmsg};

/// Datagrams closer together than this put a reader in batch mode (about 50 000 a second).
pub(crate) const BATCH_GAP: Duration = Duration::from_micros(20);

/// Receive buffers for one blocking reader and what the last receive put in them.
///
/// A reader sleeps in one `recvfrom` while datagrams come one per wake-up, as a bare loop
/// does, and in one `recvmmsg(MSG_WAITFORONE)` while they come in bursts (the last wake-up
/// found several, or they arrive less than [`BATCH_GAP`] apart). `recvmmsg` always tries once
/// more after the first datagram, so a lone datagram costs it a second, empty receive in the
/// kernel: at 10 000 frames a second that was most of a daemon's extra kernel time over a
/// bare forwarder.
pub(crate) struct Datagrams {
    pub(crate) buf: Vec<u8>,
    pub(crate) slots: usize,
    pub(crate) headers: MultiHeaders<SockaddrStorage>,
    pub(crate) got: Vec<(usize, Option<SocketAddr>)>,
    /// Take the next wake-up with `recvmmsg`.
    pub(crate) batch: bool,
    /// When the last wake-up returned.
    pub(crate) last: Option<Instant>,
}

impl Datagrams {
    pub(crate) fn new(slots: usize) -> Self {
        let slots = slots.clamp(1, RECV_BATCH);
        Datagrams {
            // Pages are only touched where datagrams land: a few per slot at most.
            buf: vec![0u8; slots * MAX_DATAGRAM_BYTES],
            slots,
            headers: MultiHeaders::preallocate(slots, None),
            got: Vec::with_capacity(slots),
            batch: false,
            last: None,
        }
    }

    /// Sleeps until a datagram arrives (or the socket's read timeout passes, `WouldBlock`),
    /// then takes it and, in batch mode, every other one waiting, up to the number of slots.
    /// `now` is read after the wake-up and returned for the caller's timers.
    pub(crate) fn recv(&mut self, sock: &UdpSocket) -> io::Result<(usize, Instant)> {
        let n = if self.batch || self.slots == 1 {
            self.recv_many(sock)?
        } else {
            self.recv_one(sock)?
        };
        let now = Instant::now();
        let close = self
            .last
            .is_some_and(|t| now.saturating_duration_since(t) < BATCH_GAP);
        self.batch = self.slots > 1 && (n > 1 || close);
        self.last = Some(now);
        Ok((n, now))
    }

    /// One `recvfrom` into the first slot.
    pub(crate) fn recv_one(&mut self, sock: &UdpSocket) -> io::Result<usize> {
        self.got.clear();
        // Not `UdpSocket::recv_from`: a socket whose receiving side was shut down (how a
        // connected reader is told to stop) returns without a sender address, which the
        // standard library asserts never happens.
        let (n, _, addr) = rustix::net::recvfrom(
            sock,
            &mut self.buf[..MAX_DATAGRAM_BYTES],
            rustix::net::RecvFlags::empty(),
        )?;
        self.got
            .push((n, addr.and_then(|a| SocketAddr::try_from(a).ok())));
        Ok(1)
    }

    /// One `recvmmsg(MSG_WAITFORONE)`: the first datagram, then every other one waiting.
    pub(crate) fn recv_many(&mut self, sock: &UdpSocket) -> io::Result<usize> {
        self.got.clear();
        let mut chunks = self.buf.chunks_mut(MAX_DATAGRAM_BYTES);
        let mut iovs: [[IoSliceMut<'_>; 1]; RECV_BATCH] =
            std::array::from_fn(|_| [IoSliceMut::new(chunks.next().unwrap_or_default())]);
        let msgs = recvmmsg(
            sock.as_raw_fd(),
            &mut self.headers,
            iovs[..self.slots].iter_mut(),
            MsgFlags::MSG_WAITFORONE,
            None,
        )
        .map_err(io::Error::from)?;
        for m in msgs {
            self.got.push((m.bytes, m.address.and_then(to_std)));
        }
        Ok(self.got.len())
    }

    /// The datagrams of the last receive: (bytes, sender).
    pub(crate) fn iter(&self) -> impl Iterator<Item = (&[u8], Option<SocketAddr>)> {
        self.got.iter().enumerate().map(|(i, (n, addr))| {
            let start = i * MAX_DATAGRAM_BYTES;
            (&self.buf[start..start + n], *addr)
        })
    }
}

pub(crate) fn to_std(a: SockaddrStorage) -> Option<SocketAddr> {
    a.as_sockaddr_in()
        .map(|v4| SocketAddr::from(*v4))
        .or_else(|| a.as_sockaddr_in6().map(|v6| SocketAddr::from(*v6)))
}

//! CAN frame values implementing [`embedded_can::Frame`] — [`PlainFrame`] (classic) and
//! [`FdFrame`] (classic or CAN FD), one type with room for 8 or 64 data bytes — for
//! in-process buses, logs and tests, where no driver's frame type is at hand.

use embedded_can::{Frame, Id};

/// A CAN frame held by value with room for `CAP` data bytes: classic (up to 8 data
/// bytes, or a remote frame) or, when `CAP` allows, CAN FD (a data length of
/// [`crate::wire::fd_len`]). Through [`Frame::new`] data of up to 8 bytes makes a classic
/// frame and longer data an FD frame; [`FrameValue::new_fd`] makes an FD frame of any
/// valid length that fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameValue<const CAP: usize> {
    id: Id,
    len: u8,
    data: [u8; CAP],
    remote: bool,
    fd: bool,
}

/// A classic CAN frame (identifier, up to 8 data bytes, remote flag).
pub type PlainFrame = FrameValue<8>;

/// A classic or CAN FD frame (up to 64 data bytes): what a host's CAN FD socket carries.
pub type FdFrame = FrameValue<64>;

impl<const CAP: usize> FrameValue<CAP> {
    fn of(id: Id, data: &[u8], fd: bool) -> Option<Self> {
        let mut buf = [0u8; CAP];
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            id,
            len: u8::try_from(data.len()).ok()?,
            data: buf,
            remote: false,
            fd,
        })
    }

    /// A CAN FD frame: `None` unless `data`'s length is a CAN FD data length that fits.
    pub fn new_fd(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        if crate::wire::fd_len(data.len()) != Some(data.len()) {
            return None;
        }
        Self::of(id.into(), data, true)
    }

    /// Whether it is a CAN FD frame.
    pub fn is_fd(&self) -> bool {
        self.fd
    }
}

impl<const CAP: usize> Frame for FrameValue<CAP> {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        if data.len() > 8 {
            return Self::new_fd(id, data);
        }
        Self::of(id.into(), data, false)
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        (dlc <= 8).then(|| Self {
            id: id.into(),
            len: dlc as u8,
            data: [0; CAP],
            remote: true,
            fd: false,
        })
    }

    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        self.id
    }

    fn dlc(&self) -> usize {
        usize::from(self.len)
    }

    fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            self.data.get(..usize::from(self.len)).unwrap_or(&[])
        }
    }
}

impl From<PlainFrame> for FdFrame {
    fn from(p: PlainFrame) -> Self {
        let mut data = [0u8; 64];
        if let Some(dst) = data.get_mut(..p.data.len()) {
            dst.copy_from_slice(&p.data);
        }
        Self {
            id: p.id,
            len: p.len,
            data,
            remote: p.remote,
            fd: p.fd,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::{ExtendedId, StandardId};

    #[test]
    fn fd_frames_take_only_can_fd_lengths() {
        let id = ExtendedId::new(0x18FF_1001).unwrap();
        let data = [0xA5u8; 64];
        for len in 0..=64 {
            let valid = len <= 8 || crate::wire::FD_LENGTHS.contains(&len);
            let f = FdFrame::new_fd(id, &data[..len]);
            assert_eq!(f.is_some(), valid, "{len}");
            let g = FdFrame::new(id, &data[..len]);
            assert_eq!(g.is_some(), valid, "{len}");
            if let Some(g) = g {
                assert_eq!(g.is_fd(), len > 8);
                assert_eq!(g.data(), &data[..len]);
                assert_eq!(g.dlc(), len);
            }
        }
        assert!(FdFrame::new(id, &[0; 65]).is_none());
        // A classic frame type takes no more than 8 bytes.
        assert!(PlainFrame::new(id, &[0; 12]).is_none());
        assert!(PlainFrame::new(id, &[0; 8]).is_some_and(|f| !f.is_fd()));
        let p = PlainFrame::new(StandardId::new(0x123).unwrap(), &[1, 2, 3]).unwrap();
        let f = FdFrame::from(p);
        assert!(!f.is_fd() && !f.is_extended());
        assert_eq!((f.id(), f.data()), (p.id(), p.data()));
        assert!(PlainFrame::new(id, &[1]).unwrap().is_extended());
        assert!(!p.is_extended());
        let r = FdFrame::from(PlainFrame::new_remote(id, 4).unwrap());
        assert!(r.is_remote_frame() && r.data().is_empty() && r.dlc() == 4);
        assert!(FdFrame::new(id, &[1]).unwrap().is_extended());
        assert!(!FdFrame::new(id, &[1]).unwrap().is_remote_frame());
        for dlc in 0..=9 {
            let r = FdFrame::new_remote(id, dlc);
            assert_eq!(r.is_some(), dlc <= 8, "{dlc}");
            if let Some(r) = r {
                assert!(r.is_remote_frame() && !r.is_fd() && r.data().is_empty());
                assert_eq!((r.dlc(), r.id()), (dlc, Id::Extended(id)));
            }
        }
    }
}

//! A plain classic CAN frame value implementing [`embedded_can::Frame`]: for in-process
//! buses, logs and tests, where no driver's frame type is at hand.

use embedded_can::{Frame, Id};

/// A classic CAN frame held by value (identifier, up to 8 data bytes, remote flag).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlainFrame {
    id: Id,
    len: u8,
    data: [u8; 8],
    remote: bool,
}

impl Frame for PlainFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        let mut buf = [0u8; 8];
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            id: id.into(),
            len: data.len() as u8,
            data: buf,
            remote: false,
        })
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        (dlc <= 8).then(|| Self {
            id: id.into(),
            len: dlc as u8,
            data: [0; 8],
            remote: true,
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

//! The link to the hardware server: the wire's [`HwLink`] and its [`IoxLink`] over iceoryx2
//! (defined in `qmarc_proto::link`, where the hwserver's side meets them too).

pub use qmarc_proto::link::{HwLink, IoxLink, LinkConnectError, LinkError, LinkTimeouts};

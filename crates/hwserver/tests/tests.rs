//! Integration tests of `qmarc-hwserver`: the real binary answering over iceoryx2.

mod util;

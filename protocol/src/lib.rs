//! Wire protocol between the trigger controller and the host: postcard messages in COBS frames with a CRC (no_std).

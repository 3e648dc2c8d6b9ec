//! Host side of the trigger controller: serial link, request/response client, clock model, capture records.

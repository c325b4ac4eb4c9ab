//! Sans-IO, `no_std` wire format of the Yahboom DOFBOT serial bus (see `shared/DOFBOT.md`).
#![no_std]

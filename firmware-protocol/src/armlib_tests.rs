//! Every serial layout of the crate against the bytes Yahboom's `Arm_Lib.py` (class
//! `Arm_Device`, serial variant) sends or parses. Each test names the Arm_Lib function; the
//! expected bytes are built the way that function builds them, with its checksum
//! `sum(cmd, 5) & 0xff` over the whole command (0xFF + 0xFC + 5 = 0x200, so it is the sum of
//! LEN, FUNC and the payload), not with this crate's [`crate::checksum`].
use std::vec;
use std::vec::Vec;

use crate::commands::{AnyTarget, BusId, Buzzer, Command, EveryRaw, Pose, Target};
use crate::frame::Decoder;
use crate::replies::{OffsetState, Reply, ReplyError, PING_ALIVE};
use crate::servo::ServoId;

/// `cmd.append(sum(cmd, 5) & 0xff)`, as every Arm_Lib command does.
fn armlib(mut cmd: Vec<u8>) -> Vec<u8> {
    let sum: u32 = cmd.iter().map(|&b| b as u32).sum::<u32>() + 5;
    cmd.push((sum & 0xff) as u8);
    cmd
}

/// Arm_Lib's angle to raw of servos 1..4 and 6: `int((3100 - 900) * angle / 180 + 900)`
/// (servos 2..4 take `180 - angle` first).
fn pos180(angle: u32) -> u16 {
    (2200 * angle / 180 + 900) as u16
}

fn bytes(cmd: Command) -> Vec<u8> {
    let mut buf = [0u8; 64];
    let n = cmd.encode(&mut buf).unwrap();
    buf[..n].to_vec()
}

fn servo(id: u8) -> ServoId {
    ServoId::new(id).unwrap()
}

fn hi(v: u16) -> u8 {
    (v >> 8) as u8
}

fn lo(v: u16) -> u8 {
    (v & 0xff) as u8
}

#[test]
fn arm_serial_servo_write_one_servo() {
    // Arm_serial_servo_write(1, 90, 500) and (2, 30, 1000): servo 2 is inverted.
    let p1 = pos180(90);
    let want = armlib(vec![0xFF, 0xFC, 0x07, 0x11, hi(p1), lo(p1), 0x01, 0xF4]);
    assert_eq!(want, [0xFF, 0xFC, 0x07, 0x11, 0x07, 0xD0, 0x01, 0xF4, 0xE4]);
    let cmd = Command::MoveServo {
        target: Target::new(servo(1), p1).unwrap(),
        time_ms: 500,
    };
    assert_eq!(bytes(cmd), want);
    let p2 = pos180(180 - 30);
    let want = armlib(vec![0xFF, 0xFC, 0x07, 0x12, hi(p2), lo(p2), 0x03, 0xE8]);
    let cmd = Command::MoveServo {
        target: Target::new(servo(2), p2).unwrap(),
        time_ms: 1000,
    };
    assert_eq!(bytes(cmd), want);
}

#[test]
fn arm_serial_servo_write6_all_servos() {
    // Arm_serial_servo_write6(0, 45, 90, 135, 270, 180, 1000).
    let p5 = ((3700 - 380) * 270 / 270 + 380) as u16;
    let raw = [
        pos180(0),
        pos180(180 - 45),
        pos180(180 - 90),
        pos180(180 - 135),
        p5,
        pos180(180),
    ];
    let mut cmd = vec![0xFF, 0xFC, 0x11, 0x1D];
    for r in raw {
        cmd.extend([hi(r), lo(r)]);
    }
    cmd.extend([0x03, 0xE8]);
    let got = bytes(Command::MoveAll {
        pose: Pose::new(raw).unwrap(),
        time_ms: 1000,
    });
    assert_eq!(got, armlib(cmd));
}

#[test]
fn arm_serial_servo_write_any_and_its_id_zero_form() {
    // Arm_serial_servo_write_any(7, 90, 300).
    let p = pos180(90);
    let want = armlib(vec![0xFF, 0xFC, 0x08, 0x19, 7, hi(p), lo(p), 0x01, 0x2C]);
    let cmd = Command::MoveAny {
        target: AnyTarget::new(BusId::new(7).unwrap(), p).unwrap(),
        time_ms: 300,
    };
    assert_eq!(bytes(cmd), want);
    // Arm_serial_servo_write_any(0, 90, 300) sends `FF FC 07 17 00 pH pL tH tL chk`: ten
    // bytes under a LEN of 07, which counts nine. This crate follows LEN (and the I2C
    // variant, whose 0x17 block is `pH pL tH tL`): the same bytes without the 00, whose
    // removal leaves the checksum unchanged.
    let mut lib = armlib(vec![0xFF, 0xFC, 0x07, 0x17, 0x00, hi(p), lo(p), 0x01, 0x2C]);
    lib.remove(4);
    let cmd = Command::MoveEvery {
        raw: EveryRaw::new(p).unwrap(),
        time_ms: 300,
    };
    assert_eq!(bytes(cmd), lib);
}

#[test]
fn arm_serial_servo_read_request() {
    // Arm_serial_servo_read(id): [FF FC 03 30+id chk], written twice.
    for id in 1..=6u8 {
        let want = armlib(vec![0xFF, 0xFC, 0x03, 0x30 + id]);
        assert_eq!(bytes(Command::ReadPosition(servo(id))), want);
    }
}

#[test]
fn arm_ping_servo_request() {
    // Arm_ping_servo(id): [FF FC 04 38 id chk]; the serial library never reads a reply.
    for id in [1u8, 6, 250] {
        let want = armlib(vec![0xFF, 0xFC, 0x04, 0x38, id]);
        assert_eq!(bytes(Command::Ping(BusId::new(id).unwrap())), want);
    }
}

#[test]
fn arm_serial_set_torque_set_id_offsets_buzzer_rgb_reset_version() {
    let cases: [(&str, Command, Vec<u8>); 12] = [
        (
            "Arm_serial_set_torque(1)",
            Command::Torque(true),
            vec![0x04, 0x1A, 0x01],
        ),
        (
            "Arm_serial_set_torque(0)",
            Command::Torque(false),
            vec![0x04, 0x1A, 0x00],
        ),
        (
            "Arm_serial_set_id(4)",
            Command::SetId(BusId::new(4).unwrap()),
            vec![0x04, 0x18, 4],
        ),
        (
            "Arm_serial_servo_write_offset_switch(3)",
            Command::StoreMidOffset(Some(BusId::new(3).unwrap())),
            vec![0x04, 0x1C, 3],
        ),
        (
            "Arm_serial_servo_write_offset_switch(0)",
            Command::StoreMidOffset(None),
            vec![0x04, 0x1C, 0x00],
        ),
        (
            "Arm_serial_servo_write_offset_state()",
            Command::ReadOffsetState,
            vec![0x03, 0x1B],
        ),
        (
            "Arm_Buzzer_On()",
            Command::Buzzer(Buzzer::ON),
            vec![0x04, 0x06, 0xFF],
        ),
        (
            "Arm_Buzzer_On(5)",
            Command::Buzzer(Buzzer::for_tenths(5).unwrap()),
            vec![0x04, 0x06, 5],
        ),
        (
            "Arm_Buzzer_Off()",
            Command::Buzzer(Buzzer::OFF),
            vec![0x04, 0x06, 0x00],
        ),
        (
            "Arm_RGB_set(10, 200, 30)",
            Command::Rgb {
                r: 10,
                g: 200,
                b: 30,
            },
            vec![0x06, 0x02, 10, 200, 30],
        ),
        ("Arm_reset()", Command::Reset, vec![0x04, 0x05, 0x01]),
        ("get_version()", Command::Version, vec![0x03, 0x01]),
    ];
    for (function, cmd, body) in cases {
        let mut frame = vec![0xFF, 0xFC];
        frame.extend(body);
        assert_eq!(bytes(cmd), armlib(frame), "{function}");
    }
}

/// A reply as `__receive_data` accepts it: `FF FB ext_len ext_type data.. chk` with
/// `ext_len - 2` bytes after the TYPE, the last the checksum of ext_len + ext_type + data.
fn board_reply(kind: u8, data: &[u8]) -> Vec<u8> {
    let ext_len = data.len() as u8 + 3;
    let sum: u32 = [ext_len, kind].iter().chain(data).map(|&b| b as u32).sum();
    let mut v = vec![0xFF, 0xFB, ext_len, kind];
    v.extend(data);
    v.push((sum % 256) as u8);
    v
}

fn parse(bytes: &[u8]) -> Result<Reply, ReplyError> {
    let mut dec = Decoder::replies();
    let frames: Vec<_> = dec.feed(bytes).collect();
    assert_eq!(frames.len(), 1, "{bytes:02X?}");
    Reply::parse(&frames[0].unwrap())
}

#[test]
fn parse_data_position_reply_is_position_then_echo() {
    // __parse_data, TYPE 0x0A: servo_H = data[0], servo_L = data[1], id = data[2];
    // Arm_serial_servo_read accepts it when id == 0x30 + id.
    for (id, raw) in [(1u8, 2000u16), (5, 380), (6, 3100)] {
        let bytes = board_reply(0x0A, &[hi(raw), lo(raw), 0x30 + id]);
        let reply = Reply::Position {
            servo: Some(servo(id)),
            raw,
        };
        assert_eq!(parse(&bytes), Ok(reply));
        let mut buf = [0u8; 16];
        let n = reply.encode(&mut buf).unwrap();
        assert_eq!(&buf[..n], &bytes[..]);
    }
    // The 2-byte form without the echo stays accepted.
    let bytes = board_reply(0x0A, &[0x07, 0xD0]);
    let reply = Reply::Position {
        servo: None,
        raw: 2000,
    };
    assert_eq!(parse(&bytes), Ok(reply));
    // The echo-first reading of the old layout is refused: 0xD0 is no 0x30+id.
    let old = board_reply(0x0A, &[0x31, 0x07, 0xD0]);
    assert_eq!(
        parse(&old),
        Err(ReplyError::BadValue {
            kind: 0x0A,
            value: 0xD0
        })
    );
}

#[test]
fn ping_status_of_one_byte_and_of_id_and_status() {
    // The I2C Arm_ping_servo reads one status byte: 0xDA alive, 0 no answer, else an error.
    for (status, alive) in [(0xDA, true), (0x00, false), (0x01, false)] {
        let one = parse(&board_reply(0x38, &[status])).unwrap();
        assert_eq!(one, Reply::Ping { id: None, status });
        assert_eq!(one.ping_alive(), alive);
        let two = parse(&board_reply(0x38, &[4, status])).unwrap();
        assert_eq!(
            two,
            Reply::Ping {
                id: Some(4),
                status
            }
        );
        assert_eq!(two.ping_alive(), alive);
    }
    assert_eq!(PING_ALIVE, 0xDA);
}

#[test]
fn parse_data_state_version_and_action_count() {
    // Arm_serial_servo_write_offset_state reads TYPE 0x33 (FUNC_UART_STATE); get_version
    // TYPE 0x01; Arm_Read_Action_Num TYPE 0x22: each one data byte.
    let cases = [
        (0x33, 0u8, Reply::OffsetState(OffsetState::NotFound)),
        (0x33, 1, Reply::OffsetState(OffsetState::Ok)),
        (0x33, 2, Reply::OffsetState(OffsetState::Failed)),
        (0x01, 3, Reply::Version(3)),
        (0x22, 9, Reply::ActionCount(9)),
    ];
    for (kind, value, reply) in cases {
        assert_eq!(parse(&board_reply(kind, &[value])), Ok(reply));
    }
}

// The I2C variant of Arm_Lib (smbus, bus 1, address 0x15): the transactions of each command.

use crate::i2c::{i2c_reply, Transaction as T, READ_WAIT_US, STATE_WAIT_US};

fn i2c(cmd: Command) -> Vec<T> {
    cmd.to_i2c().as_slice().to_vec()
}

fn byte(reg: u8, value: u8) -> T {
    T::WriteByte { reg, value }
}

#[test]
fn i2c_servo_writes_are_arm_lib_block_writes() {
    // Arm_serial_servo_write(1, 90, 500): write_i2c_block_data(0x15, 0x11, [pH, pL, tH, tL]).
    let p = pos180(90);
    let cmd = Command::MoveServo {
        target: Target::new(servo(1), p).unwrap(),
        time_ms: 500,
    };
    assert_eq!(i2c(cmd), [T::block(0x11, &[0x07, 0xD0, 0x01, 0xF4])]);
    // Arm_serial_servo_write6(0, 45, 90, 135, 270, 180, 1000): [tH, tL] to 0x1e, then the
    // twelve position bytes to 0x1d.
    let raw = [900u16, 2550, 2000, 1450, 3700, 3100];
    let data: Vec<u8> = raw.iter().flat_map(|r| [hi(*r), lo(*r)]).collect();
    let cmd = Command::MoveAll {
        pose: Pose::new(raw).unwrap(),
        time_ms: 1000,
    };
    assert_eq!(
        i2c(cmd),
        [T::block(0x1E, &[0x03, 0xE8]), T::block(0x1D, &data)]
    );
    // Arm_serial_servo_write_any(7, 90, 300) and (0, 90, 300).
    let cmd = Command::MoveAny {
        target: AnyTarget::new(BusId::new(7).unwrap(), p).unwrap(),
        time_ms: 300,
    };
    assert_eq!(i2c(cmd), [T::block(0x19, &[7, 0x07, 0xD0, 0x01, 0x2C])]);
    let cmd = Command::MoveEvery {
        raw: EveryRaw::new(p).unwrap(),
        time_ms: 300,
    };
    assert_eq!(i2c(cmd), [T::block(0x17, &[0x07, 0xD0, 0x01, 0x2C])]);
}

#[test]
fn i2c_reads_pings_and_state_are_request_wait_read() {
    // Arm_serial_servo_read(id): write_byte_data(0x15, 0x30+id, 0), sleep(0.003),
    // read_word_data(0x15, 0x30+id).
    for id in 1..=6u8 {
        assert_eq!(
            i2c(Command::ReadPosition(servo(id))),
            [
                byte(0x30 + id, 0),
                T::Wait { us: 3_000 },
                T::ReadWord { reg: 0x30 + id }
            ]
        );
    }
    // Arm_ping_servo(4): write_byte_data(0x15, 0x38, 4), sleep(.003), read_byte_data(0x15, 0x38).
    assert_eq!(
        i2c(Command::Ping(BusId::new(4).unwrap())),
        [
            byte(0x38, 4),
            T::Wait { us: 3_000 },
            T::ReadByte { reg: 0x38 }
        ]
    );
    // Arm_serial_servo_write_offset_state(): write_byte_data(0x15, 0x1b, 1), sleep(.001),
    // read_byte_data(0x15, 0x1b); Arm_get_hardversion(): the same on 0x01.
    assert_eq!(
        i2c(Command::ReadOffsetState),
        [
            byte(0x1B, 1),
            T::Wait { us: 1_000 },
            T::ReadByte { reg: 0x1B }
        ]
    );
    assert_eq!(
        i2c(Command::Version),
        [
            byte(0x01, 1),
            T::Wait { us: 1_000 },
            T::ReadByte { reg: 0x01 }
        ]
    );
    assert_eq!((READ_WAIT_US, STATE_WAIT_US), (3_000, 1_000));
}

#[test]
fn i2c_byte_commands_are_arm_lib_byte_writes() {
    let cases = [
        (
            "Arm_serial_set_torque(1)",
            Command::Torque(true),
            byte(0x1A, 1),
        ),
        (
            "Arm_serial_set_torque(0)",
            Command::Torque(false),
            byte(0x1A, 0),
        ),
        (
            "Arm_serial_set_id(4)",
            Command::SetId(BusId::new(4).unwrap()),
            byte(0x18, 4),
        ),
        (
            "Arm_serial_servo_write_offset_switch(3)",
            Command::StoreMidOffset(Some(BusId::new(3).unwrap())),
            byte(0x1C, 3),
        ),
        (
            "Arm_serial_servo_write_offset_switch(0)",
            Command::StoreMidOffset(None),
            byte(0x1C, 0),
        ),
        (
            "Arm_Buzzer_On()",
            Command::Buzzer(Buzzer::ON),
            byte(0x06, 0xFF),
        ),
        (
            "Arm_Buzzer_Off()",
            Command::Buzzer(Buzzer::OFF),
            byte(0x06, 0),
        ),
        ("Arm_reset()", Command::Reset, byte(0x05, 1)),
        (
            "Arm_RGB_set(10, 200, 30)",
            Command::Rgb {
                r: 10,
                g: 200,
                b: 30,
            },
            T::block(0x02, &[10, 200, 30]),
        ),
    ];
    for (function, cmd, want) in cases {
        assert_eq!(i2c(cmd), [want], "{function}");
    }
}

#[test]
fn i2c_position_word_is_swapped_and_zero_is_a_failed_read() {
    // Arm_serial_servo_read: pos = (pos >> 8 & 0xff) | (pos << 8 & 0xff00); 0 = failed. The
    // board sends 0x07 0xD0 (2000); SMBus delivers the word little-endian: 0xD007.
    let read = Command::ReadPosition(servo(2));
    let got = i2c_reply(&read, 0xD007).unwrap();
    assert_eq!(
        got,
        Some(Reply::Position {
            servo: Some(servo(2)),
            raw: 2000
        })
    );
    let armlib_swap = |pos: u32| ((pos >> 8) & 0xff) | ((pos << 8) & 0xff00);
    assert_eq!(armlib_swap(0xD007), 2000);
    assert_eq!(
        i2c_reply(&read, 0).unwrap(),
        Some(Reply::Position {
            servo: Some(servo(2)),
            raw: 0
        })
    );
    // Arm_ping_servo: 0xDA alive.
    let ping = Command::Ping(BusId::new(3).unwrap());
    let got = i2c_reply(&ping, 0xDA).unwrap().unwrap();
    assert!(got.ping_alive());
    assert_eq!(
        i2c_reply(&Command::ReadOffsetState, 1),
        Ok(Some(Reply::OffsetState(OffsetState::Ok)))
    );
    assert!(i2c_reply(&Command::ReadOffsetState, 7).is_err());
    assert_eq!(i2c_reply(&Command::Torque(true), 0), Ok(None));
}

#[test]
fn arm_serial_servo_read_any_request_and_reply() {
    // Arm_serial_servo_read_any(id): [FF FC 04 37 id chk]; __parse_data keeps the reply's
    // bytes as servo_H, servo_L; then d = servo_H * 256 + servo_L and
    // d = (d >> 8 & 0xff) | (d << 8 & 0xff00): the board sent the position low byte first.
    for id in [1u8, 7, 250] {
        let want = armlib(vec![0xFF, 0xFC, 0x04, 0x37, id]);
        assert_eq!(bytes(Command::ReadAny(BusId::new(id).unwrap())), want);
    }
    let (servo_h, servo_l) = (0xF8u32, 0x07u32);
    let d = servo_h * 256 + servo_l;
    let d = ((d >> 8) & 0xff) | ((d << 8) & 0xff00);
    assert_eq!(d, 2040);
    let reply = board_reply(0x0A, &[0xF8, 0x07, 0x37]);
    assert_eq!(parse(&reply), Ok(Reply::AnyPosition { raw: 2040 }));
    let mut buf = [0u8; 16];
    let n = Reply::AnyPosition { raw: 2040 }.encode(&mut buf).unwrap();
    assert_eq!(&buf[..n], &reply[..]);
}

#[test]
fn i2c_read_any_is_request_wait_read_word_swapped() {
    // Arm_serial_servo_read_any(7): write_byte_data(0x15, 0x37, 7), sleep(0.003),
    // read_word_data(0x15, 0x37), pos = (pos >> 8 & 0xff) | (pos << 8 & 0xff00).
    let read = Command::ReadAny(BusId::new(7).unwrap());
    assert_eq!(
        i2c(read),
        [
            byte(0x37, 7),
            T::Wait { us: 3_000 },
            T::ReadWord { reg: 0x37 }
        ]
    );
    assert_eq!(
        i2c_reply(&read, 0xF807),
        Ok(Some(Reply::AnyPosition { raw: 2040 }))
    );
}

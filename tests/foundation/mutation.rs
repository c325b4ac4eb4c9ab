//! Random and mutated bytes into every reader: Ok or Err, never a panic.
use super::*;
use proptest::prelude::*;

fn seeds() -> Vec<(Format, Vec<u8>)> {
    let c = sample_cloud(12);
    let faces = vec![[0u32, 1, 2], [2, 3, 4], [5, 6, 7]];
    let ply_bin = cloud::write_ply_bytes(&c, Some(&faces), PlyPrecision::F32);
    let ply_ascii = b"ply\nformat ascii 1.0\ncomment c\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\nelement range_grid 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0 1\n1 0 0 2\n0 1 0 3\n3 0 1 2\n0\n1 2\n".to_vec();
    let mut stl = vec![0u8; 80];
    stl.extend_from_slice(&2u32.to_le_bytes());
    for k in 0..2u8 {
        stl.extend_from_slice(&[0u8; 12]);
        for v in 0..9 {
            stl.extend_from_slice(&((v + k) as f32).to_le_bytes());
        }
        stl.extend_from_slice(&[0, 0]);
    }
    let stl_ascii = b"solid a\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid a\n".to_vec();
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf -1 -2 -3\n".to_vec();
    let off = b"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n4 0 1 3 2\n".to_vec();
    let pcd = b"VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3 4\n5 6 7 8\n".to_vec();
    let mut pcd_bin =
        b"FIELDS x y z\nSIZE 4 4 8\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 2\nDATA binary\n".to_vec();
    pcd_bin.extend_from_slice(&[1u8; 32]);
    let xyz = b"x y z nx ny nz\n1 2 3 0 0 1\n4,5,6,1,0,0\n".to_vec();
    vec![
        (Format::Ply, ply_bin),
        (Format::Ply, ply_ascii),
        (Format::Stl, stl),
        (Format::Stl, stl_ascii),
        (Format::Obj, obj),
        (Format::Off, off),
        (Format::Pcd, pcd),
        (Format::Pcd, pcd_bin),
        (Format::Xyz, xyz),
    ]
}

#[derive(Debug, Clone)]
enum Edit {
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Truncate(usize),
    Digit(usize, u8),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Flip(i, b)),
        (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(i, b)| Edit::Insert(i, b)),
        (any::<usize>(), 1usize..16).prop_map(|(i, n)| Edit::Delete(i, n)),
        any::<usize>().prop_map(Edit::Truncate),
        (any::<usize>(), b'0'..=b'9').prop_map(|(i, d)| Edit::Digit(i, d)),
    ]
}

fn apply(mut bytes: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let n = bytes.len().max(1);
        match e {
            Edit::Flip(i, b) => {
                if !bytes.is_empty() {
                    bytes[i % n] ^= b | 1;
                }
            }
            Edit::Insert(i, b) => {
                let at = i % (bytes.len() + 1);
                bytes.splice(at..at, b.iter().copied());
            }
            Edit::Delete(i, k) => {
                let at = i % n;
                let end = (at + k).min(bytes.len());
                if at < end {
                    bytes.drain(at..end);
                }
            }
            Edit::Truncate(i) => bytes.truncate(i % n),
            Edit::Digit(i, d) => {
                if !bytes.is_empty() {
                    bytes[i % n] = *d;
                }
            }
        }
    }
    bytes
}

const FORMATS: [Format; 6] = [
    Format::Ply,
    Format::Stl,
    Format::Obj,
    Format::Off,
    Format::Pcd,
    Format::Xyz,
];

proptest! {
    #![proptest_config(ProptestConfig { cases: 10_000, failure_persistence: None, ..ProptestConfig::default() })]

    /// Every reader gets 10,000 mutated versions of valid files of its format.
    #[test]
    fn mutated_files_never_panic(seed in 0usize..9, edits in proptest::collection::vec(edit(), 1..6), other in 0usize..6) {
        let seeds = seeds();
        let (format, bytes) = &seeds[seed];
        let mutated = apply(bytes.clone(), &edits);
        let _ = cloud::parse(&mutated, *format);
        // The same bytes through a reader of another format as well.
        let _ = cloud::parse(&mutated, FORMATS[other]);
    }

    /// Pure random bytes into every reader.
    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        for f in FORMATS {
            let _ = cloud::parse(&bytes, f);
        }
    }
}

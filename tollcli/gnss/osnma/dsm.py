"""Digital signature messages (OSNMA SIS ICD §3.2, §6.2–6.3): the public key and the TESLA root key.

* The **Merkle tree** file of the European GNSS Service Centre gives the root (node ``j=4, i=0``, 256 bits);
  a **public key** file gives its id, type and compressed point. A key from a file is checked against the
  tree like a DSM-PKR: the leaf ``NPKT ‖ NPKID ‖ NPK`` hashed with SHA-256 up four levels with the tree file's
  nodes (:func:`merkle_root_of`).
* **DSM-PKR** (DSM id 12–15): ``NB_DP`` (4) ``MID`` (4) ``ITN`` (1024: four intermediate nodes) ``NPKT`` (4)
  ``NPKID`` (4) ``NPK`` (264 for P-256, 536 for P-521) and padding ``P_DP`` = the first bits of
  SHA-256(root ‖ leaf). Verified when the leaf hashes up to the root and the padding matches.
* **DSM-KROOT** (DSM id 0–11): ``NB_DK`` ``PKID`` ``CIDKR`` ``NMACK`` ``HF`` ``MF`` ``KS`` ``TS`` ``MACLT`` ``KROOT_R`` ``MO``
  ``WN_K`` ``TOWH_K`` ``ALPHA`` (104 bits with the NMA header) ``KROOT`` (KS bits) ``DS`` (ECDSA signature r ‖ s:
  512 bits P-256/SHA-256, 1056 bits P-521/SHA-512) ``P_DK``. The signed message is the NMA header followed by
  ``CIDKR`` … ``KROOT``; the padding is the first bits of SHA-256(message ‖ DS). Verified with the ``cryptography``
  package.
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass, field

from tollcli.errors import UsageError
from tollcli.gnss.osnma.bits import from_bytes, from_hex, from_int, to_bytes, uint

#: NB_DK → (blocks, bits); NB_DP → (blocks, bits)
NB_DK = {1: (7, 728), 2: (8, 832), 3: (9, 936), 4: (10, 1040), 5: (11, 1144), 6: (12, 1248), 7: (13, 1352), 8: (14, 1456)}
NB_DP = {5: (11, 1144), 7: (13, 1352), 8: (14, 1456), 9: (15, 1560), 10: (16, 1664)}
#: NPKT → (curve name, public key bits, signature bits)
NPKT = {1: ("P-256", 264, 512), 3: ("P-521", 536, 1056)}
NPKT_OAM = 4
KEY_SIZES = (96, 104, 112, 120, 128, 160, 192, 224, 256)
TAG_SIZES = (10, 12, 14, 16, 18, 20, 24, 28, 32, 40)


@dataclass
class PublicKey:
    pkid: int
    npkt: int  # 1 P-256/SHA-256, 3 P-521/SHA-512
    point: bytes  # compressed
    mid: int
    verified: bool  # checked against the Merkle root (from the stream or the tree file)

    @property
    def leaf_bits(self) -> str:
        return from_int(self.npkt, 4) + from_int(self.pkid, 4) + from_bytes(self.point)


@dataclass
class MerkleTree:
    root: str  # 256 bits
    nodes: dict[tuple[int, int], bytes] = field(default_factory=dict)  # (j, i) → node


def _xml_text(path: str | os.PathLike) -> str:
    try:
        with open(path, encoding="utf-8") as stream:
            return "".join(line.strip() for line in stream)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except UnicodeDecodeError as exc:  # a damaged file: GSC files are UTF-8 XML
        raise UsageError(f"{path}: not a UTF-8 XML file (byte {exc.start})") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot read ({exc.strerror or exc})") from None


def read_merkle_tree(path: str | os.PathLike) -> MerkleTree:
    """The Merkle tree file (GSC format): its root and the nodes it lists."""
    nodes = {}
    for j, i, x in re.findall(r"<TreeNode><j>(\d+)</j><i>(\d+)</i>.*?<x_ji>([0-9A-Fa-f]+)</x_ji>", _xml_text(path)):
        nodes[(int(j), int(i))] = bytes.fromhex(x)
    if (4, 0) not in nodes:
        raise UsageError(f"{path}: no Merkle tree root (TreeNode j=4, i=0)")
    return MerkleTree(from_bytes(nodes[(4, 0)]), nodes)


def merkle_root_of(leaf_bits: str, mid: int, intermediate: list[bytes]) -> str:
    """The root a leaf hashes up to with its four intermediate nodes (the sibling left of an odd index)."""
    node = hashlib.sha256(to_bytes(leaf_bits)).digest()
    for sibling in intermediate:
        node = hashlib.sha256(node + sibling if mid % 2 == 0 else sibling + node).digest()
        mid //= 2
    return from_bytes(node)


def read_public_key(path: str | os.PathLike, tree: MerkleTree | None = None) -> PublicKey:
    """A public key file (GSC format); ``verified`` when the tree file holds its path up to the root."""
    text = _xml_text(path)
    try:
        pkid = int(re.findall(r"<PKID>(\d+)</PKID>", text)[0])
        kind = re.findall(r"<PKType>(.*?)</PKType>", text)[0]
        mid = int(re.findall(r"<i>(\d+)</i>", text)[0])
        point = bytes.fromhex(re.findall(r"<point>([0-9A-Fa-f]+)</point>", text)[0])
    except (IndexError, ValueError):
        raise UsageError(f"{path}: not an OSNMA public key file (PKID, PKType, i and point expected)") from None
    npkt = 1 if "P-256" in kind else 3 if "P-521" in kind else 0
    if npkt == 0:
        raise UsageError(f"{path}: public key type {kind!r} is neither P-256 nor P-521")
    key = PublicKey(pkid, npkt, point, mid, verified=False)
    if tree is not None:
        path_nodes, index = [], mid
        for level in range(4):
            path_nodes.append(tree.nodes.get((level, index ^ 1)))
            index //= 2
        key.verified = None not in path_nodes and merkle_root_of(key.leaf_bits, mid, path_nodes) == tree.root
    return key


@dataclass
class PkrResult:
    key: PublicKey | None
    verified: bool
    why: str  # empty when verified


def verify_pkr(message: str, merkle_root: str) -> PkrResult:
    """A reassembled DSM-PKR → the new public key, checked against the Merkle root."""
    nb, mid, itn, npkt, npkid = uint(message[0:4]), uint(message[4:8]), message[8:1032], uint(message[1032:1036]), uint(message[1036:1040])
    if nb not in NB_DP:
        return PkrResult(None, False, f"DSM-PKR NB_DP {nb} is reserved")
    size = NB_DP[nb][1]
    key_bits = NPKT[npkt][1] if npkt in NPKT else size - 1040 if npkt == NPKT_OAM else 0
    if key_bits <= 0:
        return PkrResult(None, False, f"DSM-PKR key type NPKT {npkt} is reserved")
    npk = message[1040 : 1040 + key_bits]
    padding = message[1040 + key_bits : size]
    leaf = message[1032 : 1040 + key_bits]
    nodes = [to_bytes(itn[256 * k : 256 * (k + 1)]) for k in range(4)]
    root_ok = merkle_root_of(leaf, mid, nodes) == merkle_root
    pad_ok = from_bytes(hashlib.sha256(to_bytes(merkle_root + leaf)).digest())[: len(padding)] == padding
    key = PublicKey(npkid, npkt, to_bytes(npk), mid, verified=root_ok and pad_ok) if npkt in NPKT else None
    why = "" if root_ok and pad_ok else ("the public key does not hash up to the Merkle root" if not root_ok else "DSM-PKR padding does not match")
    return PkrResult(key, root_ok and pad_ok, why)


@dataclass
class Kroot:
    nma_header: str
    pkid: int
    cid: int
    nmack: int
    hf: int
    mf: int
    key_bits: int
    tag_bits: int
    maclt: int
    wn_k: int
    towh_k: int
    alpha: str
    kroot: str
    verified: bool
    why: str


def verify_ecdsa(key: PublicKey, message: bytes, signature: bytes) -> bool:
    """ECDSA (P-256/SHA-256 or P-521/SHA-512) over ``message``; ``signature`` is r ‖ s."""
    from cryptography.exceptions import InvalidSignature
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.hazmat.primitives.asymmetric.utils import encode_dss_signature

    curve, digest = (ec.SECP256R1(), hashes.SHA256()) if key.npkt == 1 else (ec.SECP521R1(), hashes.SHA512())
    try:
        public = ec.EllipticCurvePublicKey.from_encoded_point(curve, key.point)
    except ValueError:
        return False
    half = len(signature) // 2
    der = encode_dss_signature(int.from_bytes(signature[:half], "big"), int.from_bytes(signature[half:], "big"))
    try:
        public.verify(der, message, ec.ECDSA(digest))
    except InvalidSignature:
        return False
    return True


def verify_kroot(nma_header: str, message: str, keys: dict[int, PublicKey]) -> Kroot:
    """A reassembled DSM-KROOT → the chain parameters and root key, its signature checked with key ``PKID``."""
    f = [uint(message[a:b]) for a, b in ((0, 4), (4, 8), (8, 10), (10, 12), (12, 14), (14, 16), (16, 20), (20, 24), (24, 32),
                                         (34, 36), (36, 48), (48, 56))]  # fmt: skip
    nb, pkid, cid, nmack, hf, mf, ks, ts, maclt, mo, wn_k, towh_k = f
    key_bits = KEY_SIZES[ks] if ks < len(KEY_SIZES) else 0
    tag_bits = TAG_SIZES[ts] if ts < len(TAG_SIZES) else 0
    alpha, kroot = message[56:104], message[104 : 104 + key_bits]
    out = Kroot(nma_header, pkid, cid, nmack, hf, mf, key_bits, tag_bits, maclt, wn_k, towh_k, alpha, kroot, False, "")
    key = keys.get(pkid)
    if nb not in NB_DK or key_bits == 0 or tag_bits == 0:
        out.why = "DSM-KROOT has a reserved field value"
    elif key is None or not key.verified:
        out.why = f"no verified public key with PKID {pkid}"
    else:
        size = NB_DK[nb][1]
        sig_bits = NPKT[key.npkt][2]
        signature = message[104 + key_bits : 104 + key_bits + sig_bits]
        padding = message[104 + key_bits + sig_bits : size]
        signed = nma_header + message[8:104 + key_bits]
        pad_ok = from_bytes(hashlib.sha256(to_bytes(signed + signature)).digest())[: len(padding)] == padding
        sig_ok = len(signature) == sig_bits and verify_ecdsa(key, to_bytes(signed), to_bytes(signature))
        out.verified = pad_ok and sig_ok and size - 104 - key_bits - sig_bits >= 0
        out.why = "" if out.verified else ("the ECDSA signature does not verify" if not sig_ok else "DSM-KROOT padding does not match")
    return out


def hex_of(bits: str) -> str:
    """A bit string → hexadecimal (for messages and tables)."""
    return to_bytes(bits).hex() if bits else ""


def bits_of_hex(text: str) -> str:
    return from_hex(text)

"""Writes the seed corpora of the fuzz harnesses (tests/fuzz/corpus/{csv,apng,video}).

Valid seeds come from the project's own generator (bsp-synth: a 2-clip, 10-frame,
64x48 dataset, byte-identical for a given seed); the regression seeds are the hostile
inputs of issue 15 (docs/security.md) built from them: a second IHDR, an fcTL outside the
canvas, 30000x30000 and 100000x100000 headers, a negative frame.idx, CR-only line ends,
non-UTF-8 bytes, a zero camera width, an HLS playlist and a concat script named .mp4, and
more. Files named found_* are inputs on which a harness found a bug (kept as regression
seeds, and read by tests/cpp). The corpora are committed; run this again (needs bsp_fast importable) only to
change them:

    PYTHONPATH=python python tests/fuzz/make_seeds.py
"""
from __future__ import annotations

import pathlib
import re
import subprocess
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
CORPUS = HERE / "corpus"
sys.path.insert(0, str(HERE.parent / "python"))  # the tests' data helpers
from bsp_testdata import png_chunk, png_chunks  # noqa: E402


# ---------------------------------------------------------------- helpers
def split_row(line: bytes) -> list[bytes]:
    """Cells of one CSV line, quotes kept (list cells are quoted and hold commas)."""
    cells, cur, quoted = [], bytearray(), False
    for b in line:
        if b == ord('"'):
            quoted = not quoted
        if b == ord(",") and not quoted:
            cells.append(bytes(cur))
            cur = bytearray()
        else:
            cur.append(b)
    cells.append(bytes(cur))
    return cells


def set_cell(text: bytes, column: str, line: int, value: bytes) -> bytes:
    """data.csv with the cell of `column` on `line` (header = line 1) replaced."""
    lines = text.split(b"\n")
    header = lines[0].split(b",")
    row = split_row(lines[line - 1])
    row[header.index(column.encode())] = value
    lines[line - 1] = b",".join(row)
    return b"\n".join(lines)


def replace_chunk(data: bytes, index: int, kind: bytes, body: bytes) -> bytes:
    pos, _, n = png_chunks(data)[index]
    return data[:pos] + png_chunk(kind, body) + data[pos + 12 + n:]


def body(data: bytes, index: int) -> bytes:
    pos, _, n = png_chunks(data)[index]
    return data[pos + 8:pos + 8 + n]


def first(data: bytes, kind: bytes, nth: int = 0) -> int:
    return [i for i, (_, k, _) in enumerate(png_chunks(data)) if k == kind][nth]


def be32(v: int) -> bytes:
    return (v & 0xFFFFFFFF).to_bytes(4, "big")


# ---------------------------------------------------------------- seeds
def compact(text: bytes) -> bytes:
    """The same rows with every decimal number cut to 3 digits after the point (a row of
    the synthetic data is ~11 KB, ~4 KB after this: small seeds mutate faster)."""
    return re.sub(rb"(\d\.\d{3})\d+", rb"\1", text)


def csv_seeds(text: bytes) -> dict[str, bytes]:
    lines = text.split(b"\n")
    full = b"\n".join(lines[:3]) + b"\n"  # header + 2 rows, as written
    lines = compact(text).split(b"\n")
    one = b"\n".join(lines[:2]) + b"\n"  # header + 1 row
    two = b"\n".join(lines[:3]) + b"\n"
    header = lines[0]
    seeds = {
        "synth_2rows.csv": full,
        "synth_1row_compact.csv": one,
        "header_only.csv": header + b"\n",
        "crlf.csv": two.replace(b"\n", b"\r\n"),
        # issue 15 regression seeds
        "neg_frame_idx.csv": set_cell(two, "frame.idx", 3, b"-3"),
        "huge_frame_idx.csv": set_cell(two, "frame.idx", 2, b"99999999999999999999"),
        "cr_only.csv": two.replace(b"\n", b"\r"),
        "non_utf8_id.csv": set_cell(two, "id", 2, b"ab\xff\xfecd"),
        "non_utf8_path.csv": set_cell(two, "camera.recording", 2, b"clips/\xc3(x.mp4"),
        "non_utf8_number.csv": set_cell(two, "world.frame", 2, b"1\x802"),
        "zero_width.csv": set_cell(two, "camera.width", 2, b"0"),
        "neg_height.csv": set_cell(two, "camera.height", 3, b"-600"),
        "absurd_width.csv": set_cell(two, "camera.width", 2, b"1000000"),
        "neg_pedestrian.csv": set_cell(two, "pedestrian.idx", 2, b"-1"),
        "truncated_row.csv": two[: len(one) + (len(two) - len(one)) // 2],
        "duplicate_row.csv": two + lines[2] + b"\n",
        "unterminated_quote.csv": set_cell(one, "camera.transform", 2, b'"[1.0, 2.0'),
        "short_list.csv": set_cell(one, "frame.pedestrian.velocity", 2, b'"[1.0, 2.0]"'),
        "nan_inf.csv": set_cell(set_cell(one, "frame.pedestrian.velocity", 2,
                                         b'"[nan, inf, -1e400]"'), "world.frame", 2, b"1e3"),
        "empty_cells.csv": set_cell(set_cell(one, "frame.pedestrian.is_crossing", 2, b""),
                                    "frame.pedestrian.pose.camera", 2, b""),
        "nul_byte.csv": set_cell(one, "pedestrian.model", 2, b"walker\x00x"),
        "renamed_crossing.csv": one.replace(b"frame.pedestrian.is_crossing",
                                            b"frame.pedestrian.is_on_driving_lane"),
        "missing_column.csv": one.replace(b"world.map,", b"", 1),
    }
    return seeds


def apng_seeds(apng: bytes) -> dict[str, bytes]:
    ihdr = first(apng, b"IHDR")
    w = int.from_bytes(body(apng, ihdr)[:4], "big")
    h = int.from_bytes(body(apng, ihdr)[4:8], "big")

    def with_ihdr(width: int, height: int) -> bytes:
        return replace_chunk(apng, ihdr, b"IHDR", be32(width) + be32(height) + body(apng, ihdr)[8:])

    fctl2 = first(apng, b"fcTL", 2)
    pos2 = png_chunks(apng)[fctl2][0]
    second_ihdr = apng[:pos2] + png_chunk(b"IHDR", be32(2 * w) + be32(2 * h) + body(apng, ihdr)[8:]) \
        + apng[pos2:]
    fc = bytearray(body(apng, fctl2))  # seq, w, h, x, y, delay num/den, dispose, blend
    outside = bytes(fc[:12]) + be32(w - 2) + bytes(fc[16:])  # x offset: right edge past w
    fc_big = bytes(fc[:4]) + be32(w + 5) + bytes(fc[8:])
    actl = first(apng, b"acTL")
    iend = first(apng, b"IEND")
    iend_pos = png_chunks(apng)[iend][0]
    pal = first(apng, b"PLTE")
    crc_pos = png_chunks(apng)[fctl2][0] + 8 + png_chunks(apng)[fctl2][2]
    bad_crc = apng[:crc_pos] + bytes([apng[crc_pos] ^ 0x55]) + apng[crc_pos + 1:]
    fctl5 = png_chunks(apng)[first(apng, b"fcTL", 5)][0]
    plain = apng[:8] + b"".join(apng[p:p + 12 + n] for p, k, n in png_chunks(apng)
                                 if k not in (b"acTL", b"fcTL", b"fdAT"))
    return {
        "synth.apng": apng,
        "plain_png.png": plain,
        # issue 15 regression seeds
        "second_ihdr.apng": second_ihdr,
        "fctl_outside_canvas.apng": replace_chunk(apng, fctl2, b"fcTL", outside),
        "fctl_wider_than_canvas.apng": replace_chunk(apng, fctl2, b"fcTL", fc_big),
        "bomb_30000.apng": with_ihdr(30000, 30000),
        "bomb_100000.apng": with_ihdr(100000, 100000),
        "zero_width.apng": with_ihdr(0, h),
        "bad_crc.apng": bad_crc,
        "cut_in_fctl.apng": apng[:fctl5 + 20],
        "no_iend.apng": apng[:iend_pos],
        "absurd_frame_count.apng": replace_chunk(apng, actl, b"acTL", be32(1_000_000_000) + be32(0)),
        "zero_frame_count.apng": replace_chunk(apng, actl, b"acTL", be32(0) + be32(0)),
        "short_palette.apng": replace_chunk(apng, pal, b"PLTE", body(apng, pal)[:6]),
        "sequence_error.apng": replace_chunk(apng, fctl2, b"fcTL", be32(77) + bytes(fc[4:])),
        "zero_delay_den.apng": replace_chunk(apng, fctl2, b"fcTL", bytes(fc[:22]) + b"\0\0" + bytes(fc[24:])),
        "dispose_previous.apng": replace_chunk(apng, fctl2, b"fcTL", bytes(fc[:24]) + b"\x02\x01"),
    }


def video_seeds(mp4: bytes) -> dict[str, bytes]:
    # a fixed absolute path (the seeds stay byte-identical across runs); the reader must
    # refuse these containers before any named file matters
    foreign = "/tmp/bsp_fuzz/foreign.mp4"
    mdat = mp4.find(b"mdat")
    flipped = bytearray(mp4)
    for i in range(mdat + 40, min(len(mp4), mdat + 400), 37):
        flipped[i] ^= 0xA5
    return {
        "synth.mp4": mp4,
        # issue 15 regression seeds: containers that would pull in other files
        "hls_playlist.mp4": (f"#EXTM3U\n#EXT-X-TARGETDURATION:10\n#EXTINF:10.0,\n{foreign}\n"
                             "#EXT-X-ENDLIST\n").encode(),
        "hls_relative.mp4": b"#EXTM3U\n#EXTINF:10.0,\n../foreign.mp4\n#EXT-X-ENDLIST\n",
        "concat_script.mp4": f"ffconcat version 1.0\nfile '{foreign}'\n".encode(),
        # damaged files
        "truncated_half.mp4": mp4[: len(mp4) // 2],
        "truncated_header.mp4": mp4[:64],
        "flipped_mdat.mp4": bytes(flipped),
        "empty.mp4": b"",
    }


def main() -> int:
    with tempfile.TemporaryDirectory() as t:
        tmp = pathlib.Path(t)
        out = tmp / "ds"
        subprocess.run([sys.executable, "-m", "bsp_fast", "synth", str(out), "--clips", "2",
                        "--frames", "10", "--size", "64x48", "--seed", "7", "--workers", "1",
                        "--quiet"], check=True)
        text = (out / "data.csv").read_bytes()
        clips = sorted((out / "clips").iterdir())
        apng = next(p for p in clips if p.suffix == ".apng").read_bytes()
        mp4 = next(p for p in clips if p.suffix == ".mp4").read_bytes()
        corpora = {"csv": csv_seeds(text), "apng": apng_seeds(apng),
                   "video": video_seeds(mp4)}
    for name, seeds in corpora.items():
        d = CORPUS / name
        d.mkdir(parents=True, exist_ok=True)  # found_* files (fuzzer findings) are kept
        for file, data in seeds.items():
            (d / file).write_bytes(data)
        total = sum(len(v) for v in seeds.values())
        print(f"{d.relative_to(HERE.parent.parent)}: {len(seeds)} seeds, {total} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())

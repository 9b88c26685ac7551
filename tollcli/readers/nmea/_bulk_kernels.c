/* Compiled twins of the bulk NMEA reader's kernels: line framing (bulk_lines.split_block),
 * field spans (BlockLines.field_span), decimal, time-of-day and date fields (bulk_fields), and spans
 * read as decimals in one pass (BlockLines.field_decimals).
 *
 * Each function reads the block's bytes and fills arrays that the caller
 * allocated (numpy arrays passed through the buffer protocol), with exactly the
 * values the numpy versions give: tests/test_bulk_kernels.py compares the two on
 * every gpsd log and on random bytes. The numpy versions stay the reference and
 * the fallback where this module was not built.
 *
 * No numpy headers: only the buffer protocol, so the build needs nothing but a
 * C compiler and Python's headers.
 *
 * Why this file is long: one extension module is one C file; each kernel is a short loop, most of
 * the length is the argument checking and buffer release each entry point needs.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

static const double POW10[23] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11,
                                 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

/* non-zero for the bytes a line pass stops at: ',', '$', '!', '*', carriage return */
static const uint8_t CLASS[256] = {[','] = 1, ['$'] = 1, ['!'] = 1, ['*'] = 1, ['\r'] = 1};

static int hex_value(int c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

/* COMMA_AT[m]: the positions of the set bits of the byte m, lowest first (then zeros) */
static uint8_t COMMA_AT[256][8];
/* BITS[m]: how many bits of the byte m are set (a table: x86-64's baseline has no popcount instruction) */
static uint8_t BITS[256];

static void fill_comma_at(void) {
    for (int m = 0; m < 256; m++) {
        int k = 0;
        for (int bit = 0; bit < 8; bit++)
            if (m & (1 << bit)) COMMA_AT[m][k++] = (uint8_t)bit;
        BITS[m] = (uint8_t)k;
    }
}

/* the XOR of buf[a, b) (0 when b <= a), eight bytes at a time */
static unsigned xor_bytes(const uint8_t *buf, Py_ssize_t a, Py_ssize_t b) {
    uint64_t w = 0;
    for (; a + 8 <= b; a += 8) {
        uint64_t word;
        memcpy(&word, buf + a, 8);
        w ^= word;
    }
    w ^= w >> 32; w ^= w >> 16; w ^= w >> 8;
    unsigned x = (unsigned)(w & 0xFF);
    for (; a < b; a++) x ^= buf[a];
    return x;
}

/* byte i of the buffer, 0 outside it (the numpy version pads with zeros) */
#define AT(i) (((i) >= 0 && (i) < n) ? (int)buf[(i)] : 0)
/* byte k of the eight-byte head at s; within the last eight bytes of the buffer, the
 * numpy version reads the buffer's last eight bytes instead (its window index is clipped) */
#define HEAD(s, k) AT(((s) + 8 <= n ? (s) : n - 8) + (k))

static Py_ssize_t count_below(const int64_t *sorted, Py_ssize_t size, int64_t value) {
    Py_ssize_t lo = 0, hi = size;
    while (lo < hi) {
        Py_ssize_t mid = (lo + hi) / 2;
        if (sorted[mid] < value) lo = mid + 1; else hi = mid;
    }
    return lo;
}

static int check(Py_buffer *b, Py_ssize_t items, Py_ssize_t itemsize, const char *name) {
    if (b->len < items * itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: buffer too small", name);
        return 0;
    }
    return 1;
}

/* frame(buf, start, end, plain, given, computed, address, commas, first_comma, n_fields, n_special)
 *
 * buf: uint8, the block. start/end/given/computed/address/first_comma/n_fields/n_special: int64
 * with one item per line (line feeds + 1); plain: uint8 (bool), same length;
 * commas: int64 with one item per comma plus two, the last two set to the sentinel.
 */
static PyObject *frame(PyObject *self, PyObject *args) {
    Py_buffer b_buf, b_start, b_end, b_plain, b_given, b_computed, b_address, b_commas, b_first, b_nf, b_ns;
    if (!PyArg_ParseTuple(args, "y*w*w*w*w*w*w*w*w*w*w*", &b_buf, &b_start, &b_end, &b_plain, &b_given,
                          &b_computed, &b_address, &b_commas, &b_first, &b_nf, &b_ns))
        return NULL;
    PyObject *result = NULL;
    const uint8_t *buf = (const uint8_t *)b_buf.buf;
    const Py_ssize_t n = b_buf.len;
    Py_ssize_t lines = b_start.len / 8;
    Py_ssize_t n_commas = b_commas.len / 8 - 2;
    if (n_commas < 0) {
        PyErr_SetString(PyExc_ValueError, "frame: commas needs two items past the last comma");
        goto done;
    }
    if (!check(&b_end, lines, 8, "end") || !check(&b_plain, lines, 1, "plain") ||
        !check(&b_given, lines, 8, "given") || !check(&b_computed, lines, 8, "computed") ||
        !check(&b_address, lines, 8, "address") || !check(&b_first, lines, 8, "first_comma") ||
        !check(&b_nf, lines, 8, "n_fields") || !check(&b_ns, lines, 8, "n_special"))
        goto done;
    int64_t *start = b_start.buf, *end = b_end.buf, *given = b_given.buf, *computed = b_computed.buf;
    int64_t *address = b_address.buf, *commas = b_commas.buf, *first = b_first.buf, *nf = b_nf.buf, *ns = b_ns.buf;
    uint8_t *plain = b_plain.buf;
    Py_ssize_t line = 0, c = 0;
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    /* one pass per line: its commas (recorded for the whole block), its '$', '!', '*' and
     * carriage returns (counted, the last kept with the XOR of the bytes before it) */
    Py_ssize_t ls = 0;
    while (line < lines) {
        const uint8_t *nl = ls < n ? memchr(buf + ls, '\n', (size_t)(n - ls)) : NULL;
        Py_ssize_t le = nl ? (Py_ssize_t)(nl - buf) : n;
        if (!nl && line != lines - 1) { bad = 1; break; }
        Py_ssize_t e = le;
        if (e > ls && buf[e - 1] == '\r') e--;
        int android = HEAD(ls, 0) == 'N' && HEAD(ls, 1) == 'M' && HEAD(ls, 2) == 'E' && HEAD(ls, 3) == 'A' &&
                      HEAD(ls, 4) == ',';
        Py_ssize_t s = android ? ls + 5 : ls;
        Py_ssize_t n_special = 0, last = -1, c_last = c, c_first = c;
        Py_ssize_t j = ls;
        Py_ssize_t c_line = c;  /* the line's first comma */
#ifdef __SSE2__
        /* sixteen bytes at a time: the commas' positions written eight at a time from a table (where eight more fit
         * before the last comma's slot), the other bytes of CLASS visited one by one */
        for (; j + 16 <= e; j += 16) {
            __m128i v = _mm_loadu_si128((const __m128i *)(buf + j));
            unsigned cm = (unsigned)_mm_movemask_epi8(_mm_cmpeq_epi8(v, _mm_set1_epi8(',')));
            unsigned sm = (unsigned)_mm_movemask_epi8(
                _mm_or_si128(_mm_or_si128(_mm_cmpeq_epi8(v, _mm_set1_epi8('$')), _mm_cmpeq_epi8(v, _mm_set1_epi8('!'))),
                             _mm_or_si128(_mm_cmpeq_epi8(v, _mm_set1_epi8('*')), _mm_cmpeq_epi8(v, _mm_set1_epi8('\r')))));
            while (sm) {  /* in order with the commas: those before it counted first */
                Py_ssize_t at = j + __builtin_ctz(sm);
                sm &= sm - 1;
                if (at >= s) {
                    n_special++; last = at;
                    unsigned before = cm & ((1u << (at - j)) - 1u);
                    c_last = c + BITS[before & 0xFFu] + BITS[before >> 8];
                }
            }
            if (c + 16 <= n_commas) {
                for (int half = 0; half < 2; half++) {
                    unsigned byte = (cm >> (8 * half)) & 0xFFu;
                    const uint8_t *pos = COMMA_AT[byte];
                    Py_ssize_t base = j + 8 * half;
                    for (int k = 0; k < 8; k++) commas[c + k] = base + pos[k];
                    c += BITS[byte];
                }
            } else {
                while (cm) {
                    if (c >= n_commas) { bad = 1; break; }
                    commas[c++] = j + __builtin_ctz(cm);
                    cm &= cm - 1;
                }
                if (bad) break;
            }
        }
#endif
        for (; j < e && !bad; j++) {
            uint8_t ch = buf[j];
            if (CLASS[ch]) {
                if (ch == ',') {
                    if (c >= n_commas) { bad = 1; break; }
                    commas[c++] = j;
                } else if (j >= s) {
                    n_special++; last = j; c_last = c;
                }
            }
        }
        if (bad) break;
        for (Py_ssize_t k = c_line; k < c && commas[k] < s + 6; k++) c_first = k + 1;
        Py_ssize_t star = n_special > 0 ? last : e;
        Py_ssize_t framed = star + 3 < e ? star + 3 : e;
        int hi = hex_value(AT(framed - 2)), lo = hex_value(AT(framed - 1));
        int is_plain = (framed - s >= 10) && HEAD(s, 0) == '$' && AT(star < n ? star : n - 1) == '*' &&
                       n_special == 2 && star + 3 <= e && HEAD(s, 6) == ',' && hi >= 0 && lo >= 0 &&
                       HEAD(s, 1) != ',' && HEAD(s, 2) != ',' && HEAD(s, 3) != ',' && HEAD(s, 4) != ',' &&
                       HEAD(s, 5) != ',';  /* a five-character address: "$GNG,A,..." is not one */
        given[line] = (int64_t)hi * 16 + lo;
        int64_t addr = 0;
        for (int k = 5; k >= 1; k--) addr = (addr << 8) | (int64_t)HEAD(s, k);
        address[line] = addr;
        if (is_plain) {
            /* the XOR of the bytes between the '$' and the '*' */
            computed[line] = (int64_t)xor_bytes(buf, s + 1, last);
            start[line] = s;
            end[line] = framed;
            /* within the line: the commas before s + 6 and before the '*' */
            first[line] = c_first;
            nf[line] = c_last - c_first;
        } else {
            computed[line] = -1;
            start[line] = android ? ls : s;
            end[line] = e;
            first[line] = -1;  /* counted over the whole block below */
        }
        plain[line] = (uint8_t)is_plain;
        ns[line] = n_special;
        line++;
        ls = le + 1;
    }
    if (!bad && c != n_commas) bad = 1;
    for (Py_ssize_t i = 0; !bad && i < lines; i++)
        if (!plain[i]) {
            Py_ssize_t f = count_below(commas, n_commas, start[i] + 6);
            first[i] = f;
            nf[i] = count_below(commas, n_commas, end[i] - 3) - f;
        }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "frame: line or comma count does not match the buffer");
        goto done;
    }
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&b_buf); PyBuffer_Release(&b_start); PyBuffer_Release(&b_end); PyBuffer_Release(&b_plain);
    PyBuffer_Release(&b_given); PyBuffer_Release(&b_computed); PyBuffer_Release(&b_address);
    PyBuffer_Release(&b_commas); PyBuffer_Release(&b_first); PyBuffer_Release(&b_nf); PyBuffer_Release(&b_ns);
    return result;
}

/* One decimal field [s, e) of buf (n bytes): sets value, empty, has_dot and returns ok.
 * The rules of bulk_fields.decimal_numpy: the last 16 characters are examined; the field
 * is plain when they are digits with at most one point (none if integer_only) and a
 * leading minus, with at least one digit and at most 15 characters after the minus; its
 * value is the exact integer of its digits divided by the exact power of ten of its
 * places, which IEEE division rounds as float() does. Empty: NaN and ok. */
static inline int parse_decimal(const uint8_t *buf, Py_ssize_t n, int64_t s, int64_t e, int integer_only,
                                double *value, uint8_t *empty, uint8_t *has_dot) {
    int64_t len = e - s;
    if (len == 0) {
        *value = NAN; *empty = 1; *has_dot = 0;
        return 1;
    }
    *empty = 0;
    int neg = n > 0 && buf[s < n ? (s > 0 ? s : 0) : n - 1] == '-';
    int64_t from = e - 16 > s ? e - 16 : s;
    int n_bad = 0, dots = 0, places = 0;
    int64_t mantissa = 0;
    for (int64_t j = from; j < e; j++) {
        int ch = AT(j);
        if (ch >= '0' && ch <= '9') {
            mantissa = mantissa * 10 + (ch - '0');
            if (dots) places++;
        } else if (ch == '.') {
            dots++;
        } else {
            n_bad++;
        }
    }
    *has_dot = dots > 0;
    int good = n_bad == neg && dots <= (integer_only ? 0 : 1) && len - dots - neg >= 1 && len - neg <= 15;
    if (!good) {
        *value = NAN;
        return 0;
    }
    double v = dots ? (double)mantissa / POW10[places] : (double)mantissa;
    *value = neg ? -v : v;
    return 1;
}

/* decimal(buf, start, end, integer_only, value, ok, empty, has_dot)
 *
 * start/end: int64 spans; value: float64; ok/empty/has_dot: uint8 (bool).
 */
static PyObject *decimal(PyObject *self, PyObject *args) {
    Py_buffer b_buf, b_start, b_end, b_value, b_ok, b_empty, b_dot;
    int integer_only;
    if (!PyArg_ParseTuple(args, "y*y*y*pw*w*w*w*", &b_buf, &b_start, &b_end, &integer_only, &b_value, &b_ok,
                          &b_empty, &b_dot))
        return NULL;
    PyObject *result = NULL;
    const uint8_t *buf = (const uint8_t *)b_buf.buf;
    const Py_ssize_t n = b_buf.len;
    Py_ssize_t m = b_start.len / 8;
    if (!check(&b_end, m, 8, "end") || !check(&b_value, m, 8, "value") || !check(&b_ok, m, 1, "ok") ||
        !check(&b_empty, m, 1, "empty") || !check(&b_dot, m, 1, "has_dot"))
        goto done;
    const int64_t *start = b_start.buf, *end = b_end.buf;
    double *value = b_value.buf;
    uint8_t *ok = b_ok.buf, *empty = b_empty.buf, *has_dot = b_dot.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m; i++)
        ok[i] = (uint8_t)parse_decimal(buf, n, start[i], end[i], integer_only, value + i, empty + i, has_dot + i);
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&b_buf); PyBuffer_Release(&b_start); PyBuffer_Release(&b_end); PyBuffer_Release(&b_value);
    PyBuffer_Release(&b_ok); PyBuffer_Release(&b_empty); PyBuffer_Release(&b_dot);
    return result;
}

/* parse_decimal for a field of one to three digits (a GSV's numbers, nearly always), else parse_decimal itself */
static inline int small_count(const uint8_t *buf, Py_ssize_t n, int64_t s, int64_t e, double *value, uint8_t *empty,
                              uint8_t *has_dot) {
    int64_t len = e - s;
    if (len >= 1 && len <= 3 && s >= 0 && e <= n) {
        int v = 0, j;
        for (j = 0; j < len; j++) {
            unsigned d = (unsigned)buf[s + j] - '0';
            if (d > 9) break;
            v = v * 10 + (int)d;
        }
        if (j == len) {
            *value = (double)v; *empty = 0; *has_dot = 0;
            return 1;
        }
    }
    return parse_decimal(buf, n, s, e, 0, value, empty, has_dot);
}

/* Field k (1 = first after the address) of a plain line: [*s, *e). Field k starts after the line's k-th
 * comma and ends at the next comma or at the '*'; past the last field it is empty, at the '*'.
 * Returns 0 when the comma index falls before the first comma (a caller's error). */
static inline int field_bounds(const int64_t *first, const int64_t *end, const int64_t *commas, Py_ssize_t top,
                               int64_t line, int64_t k, int64_t *s, int64_t *e) {
    int64_t c = first[line] + k - 1;
    if (c > top) c = top;
    if (c < 0) return 0;
    int64_t star = end[line] - 3, a = commas[c] + 1, b = commas[c + 1];
    if (b < a) b = a;
    if (b > star) b = star;
    *s = a < star ? a : star;
    *e = b;
    return 1;
}

/* field_span(first_comma, end, commas, lines, k, s_out, e_out)
 *
 * int64 throughout; k has one item (for every line) or one per line. The rules of
 * BlockLines.field_span: field k starts after the line's k-th comma and ends at the
 * next comma or at the '*'; past the last field it is empty, at the '*'.
 */
static PyObject *field_span(PyObject *self, PyObject *args) {
    Py_buffer b_first, b_end, b_commas, b_lines, b_k, b_s, b_e;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*w*w*", &b_first, &b_end, &b_commas, &b_lines, &b_k, &b_s, &b_e))
        return NULL;
    PyObject *result = NULL;
    Py_ssize_t m = b_lines.len / 8, n_lines = b_first.len / 8, n_k = b_k.len / 8, top = b_commas.len / 8 - 2;
    if (top < 0 || (n_k != 1 && n_k != m) || b_end.len / 8 != n_lines || !check(&b_s, m, 8, "s") ||
        !check(&b_e, m, 8, "e")) {
        PyErr_SetString(PyExc_ValueError, "field_span: sizes do not match");
        goto done;
    }
    const int64_t *first = b_first.buf, *end = b_end.buf, *commas = b_commas.buf, *lines = b_lines.buf, *ks = b_k.buf;
    int64_t *so = b_s.buf, *eo = b_e.buf;
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m; i++) {
        int64_t line = lines[i];
        if (line < 0 || line >= n_lines) { bad = 1; break; }
        if (!field_bounds(first, end, commas, top, line, ks[n_k == 1 ? 0 : i], so + i, eo + i)) { bad = 1; break; }
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_IndexError, "field_span: line or field out of range");
        goto done;
    }
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&b_first); PyBuffer_Release(&b_end); PyBuffer_Release(&b_commas); PyBuffer_Release(&b_lines);
    PyBuffer_Release(&b_k); PyBuffer_Release(&b_s); PyBuffer_Release(&b_e);
    return result;
}

/* field_decimal(buf, first_comma, end, commas, lines, k, integer_only, value, ok, empty, has_dot)
 *
 * field_span and decimal in one pass: field k of each line read as a decimal (the rules of
 * both), without the spans in between. k has one item (for every line) or one per line.
 */
static PyObject *field_decimal(PyObject *self, PyObject *args) {
    Py_buffer b_buf, b_first, b_end, b_commas, b_lines, b_k, b_value, b_ok, b_empty, b_dot;
    int integer_only;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*pw*w*w*w*", &b_buf, &b_first, &b_end, &b_commas, &b_lines, &b_k,
                          &integer_only, &b_value, &b_ok, &b_empty, &b_dot))
        return NULL;
    PyObject *result = NULL;
    const uint8_t *buf = (const uint8_t *)b_buf.buf;
    const Py_ssize_t n = b_buf.len;
    Py_ssize_t m = b_lines.len / 8, n_lines = b_first.len / 8, n_k = b_k.len / 8, top = b_commas.len / 8 - 2;
    if (top < 0 || (n_k != 1 && n_k != m) || b_end.len / 8 != n_lines || !check(&b_value, m, 8, "value") ||
        !check(&b_ok, m, 1, "ok") || !check(&b_empty, m, 1, "empty") || !check(&b_dot, m, 1, "has_dot")) {
        PyErr_SetString(PyExc_ValueError, "field_decimal: sizes do not match");
        goto done;
    }
    const int64_t *first = b_first.buf, *end = b_end.buf, *commas = b_commas.buf, *lines = b_lines.buf, *ks = b_k.buf;
    double *value = b_value.buf;
    uint8_t *ok = b_ok.buf, *empty = b_empty.buf, *has_dot = b_dot.buf;
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m; i++) {
        int64_t line = lines[i];
        if (line < 0 || line >= n_lines) { bad = 1; break; }
        int64_t s, e;
        if (!field_bounds(first, end, commas, top, line, ks[n_k == 1 ? 0 : i], &s, &e)) { bad = 1; break; }
        ok[i] = (uint8_t)parse_decimal(buf, n, s, e, integer_only, value + i, empty + i, has_dot + i);
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_IndexError, "field_decimal: line or field out of range");
        goto done;
    }
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&b_buf); PyBuffer_Release(&b_first); PyBuffer_Release(&b_end); PyBuffer_Release(&b_commas);
    PyBuffer_Release(&b_lines); PyBuffer_Release(&b_k); PyBuffer_Release(&b_value); PyBuffer_Release(&b_ok);
    PyBuffer_Release(&b_empty); PyBuffer_Release(&b_dot);
    return result;
}

/* gsa_slots(buf, first_comma, end, commas, lines, n_slots, prn, row, k, n_keys, ok) -> number of satellites
 *
 * The satellite slots of GSA lines (fields 3 … 2 + n_slots[i] of lines[i], at most 32): each non-empty slot
 * is read as an integer field (the rules of parse_decimal with integer_only) and written, compacted, to
 * prn/row/k (its line's place in ``lines`` and its place among that line's satellites); n_keys[i] counts
 * them; ok[i] is cleared when a slot is not a number in 1…1023 (the look-up table's) — as
 * bulk_sentences.gsa's numpy path. prn/row/k: int64 with room for every slot; n_keys: int64; ok: uint8.
 */
static PyObject *gsa_slots(PyObject *self, PyObject *args) {
    Py_buffer b_buf, b_first, b_end, b_commas, b_lines, b_slots, b_prn, b_row, b_k, b_keys, b_ok;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*w*w*w*w*w*", &b_buf, &b_first, &b_end, &b_commas, &b_lines, &b_slots,
                          &b_prn, &b_row, &b_k, &b_keys, &b_ok))
        return NULL;
    PyObject *result = NULL;
    const uint8_t *buf = (const uint8_t *)b_buf.buf;
    const Py_ssize_t n = b_buf.len;
    Py_ssize_t m = b_lines.len / 8, n_lines = b_first.len / 8, top = b_commas.len / 8 - 2, room = b_prn.len / 8;
    if (top < 0 || b_end.len / 8 != n_lines || b_slots.len / 8 != m || b_row.len / 8 != room || b_k.len / 8 != room ||
        !check(&b_keys, m, 8, "n_keys") || !check(&b_ok, m, 1, "ok")) {
        PyErr_SetString(PyExc_ValueError, "gsa_slots: sizes do not match");
        goto done;
    }
    const int64_t *first = b_first.buf, *end = b_end.buf, *commas = b_commas.buf, *lines = b_lines.buf,
                  *slots = b_slots.buf;
    int64_t *prn = b_prn.buf, *row = b_row.buf, *kk = b_k.buf, *keys = b_keys.buf;
    uint8_t *ok = b_ok.buf;
    Py_ssize_t out = 0;
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m && !bad; i++) {
        int64_t line = lines[i];
        if (line < 0 || line >= n_lines) { bad = 1; break; }
        int64_t w = slots[i] < 0 ? 0 : (slots[i] > 32 ? 32 : slots[i]);
        int64_t present = 0;
        for (int64_t j = 0; j < w; j++) {
            int64_t s, e;
            if (!field_bounds(first, end, commas, top, line, 3 + j, &s, &e)) { bad = 1; break; }
            if (e == s) continue;
            double v;
            uint8_t empty, dot;
            int good = parse_decimal(buf, n, s, e, 1, &v, &empty, &dot);
            int64_t value = good ? (int64_t)v : -1;  /* as the numpy path: a number out of range is kept */
            if (!good || value < 1 || value > 1023) ok[i] = 0;
            if (out >= room) { bad = 1; break; }
            prn[out] = value; row[out] = i; kk[out] = present;
            out++; present++;
        }
        keys[i] = present;
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_IndexError, "gsa_slots: line or field out of range, or no room");
        goto done;
    }
    result = PyLong_FromSsize_t(out);
done:
    PyBuffer_Release(&b_buf); PyBuffer_Release(&b_first); PyBuffer_Release(&b_end); PyBuffer_Release(&b_commas);
    PyBuffer_Release(&b_lines); PyBuffer_Release(&b_slots); PyBuffer_Release(&b_prn); PyBuffer_Release(&b_row);
    PyBuffer_Release(&b_k); PyBuffer_Release(&b_keys); PyBuffer_Release(&b_ok);
    return result;
}

/* gsv_groups(buf, first_comma, end, commas, lines, groups, row, prn, elev, azim, cn0, ok) -> number of satellites
 *
 * The satellite groups of GSV lines (fields 4+4g … 7+4g of lines[i], g < groups[i]): a group whose number field
 * is not empty is written, compacted, to row (its line's place in ``lines``), prn (int64: the number, -1 when it
 * is no plain integer), elev/azim/cn0 (float64, NaN when empty or not a plain decimal); ok[i] is cleared when a
 * group of the line is not one the bulk path reads — a number not an integer in 1 … 1023, an angle or C/N0 not a
 * plain decimal, an elevation outside ±90° or an azimuth outside 0 … 360° — as bulk_sentences.gsv's numpy path.
 * row/prn/elev/azim/cn0 have room for every group; ok: uint8, set by the caller. */
static PyObject *gsv_groups(PyObject *self, PyObject *args) {
    Py_buffer b_buf, b_first, b_end, b_commas, b_lines, b_groups, b_row, b_prn, b_elev, b_azim, b_cn0, b_ok;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*w*w*w*w*w*w*", &b_buf, &b_first, &b_end, &b_commas, &b_lines, &b_groups,
                          &b_row, &b_prn, &b_elev, &b_azim, &b_cn0, &b_ok))
        return NULL;
    PyObject *result = NULL;
    const uint8_t *buf = (const uint8_t *)b_buf.buf;
    const Py_ssize_t n = b_buf.len;
    Py_ssize_t m = b_lines.len / 8, n_lines = b_first.len / 8, top = b_commas.len / 8 - 2, room = b_row.len / 8;
    if (top < 0 || b_end.len / 8 != n_lines || b_groups.len / 8 != m || b_prn.len / 8 != room ||
        b_elev.len / 8 != room || b_azim.len / 8 != room || b_cn0.len / 8 != room || !check(&b_ok, m, 1, "ok")) {
        PyErr_SetString(PyExc_ValueError, "gsv_groups: sizes do not match");
        goto done;
    }
    const int64_t *first = b_first.buf, *end = b_end.buf, *commas = b_commas.buf, *lines = b_lines.buf,
                  *groups = b_groups.buf;
    int64_t *row = b_row.buf, *prn = b_prn.buf;
    double *elev = b_elev.buf, *azim = b_azim.buf, *cn0 = b_cn0.buf;
    uint8_t *ok = b_ok.buf;
    Py_ssize_t out = 0;
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m && !bad; i++) {
        int64_t line = lines[i];
        if (line < 0 || line >= n_lines) { bad = 1; break; }
        for (int64_t g = 0; g < groups[i]; g++) {
            int64_t s, e;
            double v[4];
            uint8_t empty[4], dot[4];
            int good[4];
            for (int f = 0; f < 4; f++) {
                if (!field_bounds(first, end, commas, top, line, 4 + 4 * g + f, &s, &e)) { bad = 1; break; }
                good[f] = small_count(buf, n, s, e, v + f, empty + f, dot + f);
            }
            if (bad) break;
            if (empty[0]) continue;  /* no satellite in this group */
            int64_t number = good[0] ? (int64_t)v[0] : -1;
            int ok_number = good[0] && !dot[0] && number >= 1 && number <= 1023;
            int ok_range = (isnan(v[1]) || (v[1] >= -90.0 && v[1] <= 90.0)) && (isnan(v[2]) || (v[2] >= 0.0 && v[2] <= 360.0));
            if (!(ok_number && good[1] && good[2] && good[3] && ok_range)) ok[i] = 0;
            if (out >= room) { bad = 1; break; }
            row[out] = i; prn[out] = number; elev[out] = v[1]; azim[out] = v[2]; cn0[out] = v[3];
            out++;
        }
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_IndexError, "gsv_groups: line or field out of range, or no room");
        goto done;
    }
    result = PyLong_FromSsize_t(out);
done:
    PyBuffer_Release(&b_buf); PyBuffer_Release(&b_first); PyBuffer_Release(&b_end); PyBuffer_Release(&b_commas);
    PyBuffer_Release(&b_lines); PyBuffer_Release(&b_groups); PyBuffer_Release(&b_row); PyBuffer_Release(&b_prn);
    PyBuffer_Release(&b_elev); PyBuffer_Release(&b_azim); PyBuffer_Release(&b_cn0); PyBuffer_Release(&b_ok);
    return result;
}

/* gsv_reports(e, code, signal, chosen) -> True, or False when the rows are not in epoch order (the caller's numpy path)
 *
 * Which GSV satellite rows (int64 e: the epoch, code: constellation·1024 + number below 16·1024, signal: the signal id,
 * -1 none; in line order) stand for their satellite in their epoch, as the reference assembler keeps them: going
 * through an epoch's reports in order, a report replaces the kept one of its satellite when its signal id is lower
 * or equal, or the kept one has none. chosen: uint8, one per row, set here (1: the kept report). */
static PyObject *gsv_reports(PyObject *self, PyObject *args) {
    Py_buffer b_e, b_code, b_signal, b_chosen;
    if (!PyArg_ParseTuple(args, "y*y*y*w*", &b_e, &b_code, &b_signal, &b_chosen)) return NULL;
    PyObject *result = NULL;
    const Py_ssize_t m = b_e.len / 8;
    int64_t *kept = NULL, *touched = NULL;
    if (b_code.len / 8 != m || b_signal.len / 8 != m || b_chosen.len != m) {
        PyErr_SetString(PyExc_ValueError, "gsv_reports: sizes do not match");
        goto done;
    }
    enum { CODES = 16 * 1024 };
    kept = PyMem_Malloc(CODES * sizeof(int64_t));
    touched = PyMem_Malloc((m > 0 ? m : 1) * sizeof(int64_t));
    if (kept == NULL || touched == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    const int64_t *e = b_e.buf, *code = b_code.buf, *signal = b_signal.buf;
    uint8_t *chosen = b_chosen.buf;
    int ordered = 1;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t c = 0; c < CODES; c++) kept[c] = -1;
    Py_ssize_t n_touched = 0;
    for (Py_ssize_t i = 0; i < m; i++) {
        chosen[i] = 0;
        if (code[i] < 0 || code[i] >= CODES || (i > 0 && e[i] < e[i - 1])) { ordered = 0; break; }
        if (i > 0 && e[i] != e[i - 1]) {  /* a new epoch: its satellites start again */
            for (Py_ssize_t t = 0; t < n_touched; t++) kept[touched[t]] = -1;
            n_touched = 0;
        }
        int64_t k = kept[code[i]];
        if (k < 0) {
            kept[code[i]] = i;
            touched[n_touched++] = code[i];
            chosen[i] = 1;
        } else if (signal[i] <= signal[k] || signal[k] < 0) {
            chosen[k] = 0;
            kept[code[i]] = i;
            chosen[i] = 1;
        }
    }
    Py_END_ALLOW_THREADS
    result = ordered ? Py_True : Py_False;
    Py_INCREF(result);
done:
    PyMem_Free(kept); PyMem_Free(touched);
    PyBuffer_Release(&b_e); PyBuffer_Release(&b_code); PyBuffer_Release(&b_signal); PyBuffer_Release(&b_chosen);
    return result;
}

/* time_of_day(buf, start, end, tod, ok): hhmmss[.sss] fields → seconds after midnight
 * (float64, NaN when empty or bad) and ok (uint8: empty or good). The rules of
 * bulk_fields.time_of_day_s_numpy: six leading digits, hh <= 23, mm <= 59, the seconds
 * (from the fifth character) a plain decimal in [0, 61). */
static PyObject *time_of_day(PyObject *self, PyObject *args) {
    Py_buffer b_buf, b_start, b_end, b_tod, b_ok;
    if (!PyArg_ParseTuple(args, "y*y*y*w*w*", &b_buf, &b_start, &b_end, &b_tod, &b_ok)) return NULL;
    PyObject *result = NULL;
    const uint8_t *buf = (const uint8_t *)b_buf.buf;
    const Py_ssize_t n = b_buf.len;
    Py_ssize_t m = b_start.len / 8;
    if (!check(&b_end, m, 8, "end") || !check(&b_tod, m, 8, "tod") || !check(&b_ok, m, 1, "ok")) goto done;
    const int64_t *start = b_start.buf, *end = b_end.buf;
    double *tod = b_tod.buf;
    uint8_t *ok = b_ok.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m; i++) {
        int64_t s = start[i], e = end[i];
        tod[i] = NAN;
        if (e == s) { ok[i] = 1; continue; }
        ok[i] = 0;
        if (e - s < 6) continue;
        int d[6], digits = 1;
        for (int k = 0; k < 6; k++) {
            d[k] = AT(s + k) - '0';
            if (d[k] < 0 || d[k] > 9) digits = 0;
        }
        if (!digits) continue;
        int hh = d[0] * 10 + d[1], mm = d[2] * 10 + d[3];
        double ss;
        uint8_t empty, dot;
        if (!parse_decimal(buf, n, s + 4, e, 0, &ss, &empty, &dot)) continue;
        if (hh > 23 || mm > 59 || !(ss >= 0.0) || !(ss < 61.0)) continue;
        tod[i] = ((double)hh * 3600.0 + (double)mm * 60.0) + ss;
        ok[i] = 1;
    }
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&b_buf); PyBuffer_Release(&b_start); PyBuffer_Release(&b_end); PyBuffer_Release(&b_tod);
    PyBuffer_Release(&b_ok);
    return result;
}

static int64_t days_from_civil(int64_t y, int64_t m, int64_t d) {
    y -= m <= 2;
    int64_t era = (y >= 0 ? y : y - 399) / 400;
    int64_t yoe = y - era * 400;
    int64_t doy = (153 * ((m + 9) % 12) + 2) / 5 + d - 1;
    int64_t doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    return era * 146097 + doe - 719468;
}

/* rmc_date(buf, start, end, days, ok): ddmmyy fields → days since 1970-01-01 (int64, -1
 * when empty or bad; years 80–99 are 19xx) and ok (uint8: empty or good). */
static PyObject *rmc_date(PyObject *self, PyObject *args) {
    Py_buffer b_buf, b_start, b_end, b_days, b_ok;
    if (!PyArg_ParseTuple(args, "y*y*y*w*w*", &b_buf, &b_start, &b_end, &b_days, &b_ok)) return NULL;
    PyObject *result = NULL;
    const uint8_t *buf = (const uint8_t *)b_buf.buf;
    const Py_ssize_t n = b_buf.len;
    Py_ssize_t m = b_start.len / 8;
    if (!check(&b_end, m, 8, "end") || !check(&b_days, m, 8, "days") || !check(&b_ok, m, 1, "ok")) goto done;
    const int64_t *start = b_start.buf, *end = b_end.buf;
    int64_t *days = b_days.buf;
    uint8_t *ok = b_ok.buf;
    static const int month_days[13] = {0, 31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m; i++) {
        int64_t s = start[i], e = end[i];
        days[i] = -1;
        ok[i] = e == s;
        if (e - s != 6) continue;
        int d[6], digits = 1;
        for (int k = 0; k < 6; k++) {
            d[k] = AT(s + k) - '0';
            if (d[k] < 0 || d[k] > 9) digits = 0;
        }
        if (!digits) continue;
        int day = d[0] * 10 + d[1], month = d[2] * 10 + d[3], yy = d[4] * 10 + d[5];
        int year = yy >= 80 ? 1900 + yy : 2000 + yy;
        int leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
        if (month < 1 || month > 12 || day < 1 || day > month_days[month] + (leap && month == 2)) continue;
        days[i] = days_from_civil(year, month, day);
        ok[i] = 1;
    }
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&b_buf); PyBuffer_Release(&b_start); PyBuffer_Release(&b_end); PyBuffer_Release(&b_days);
    PyBuffer_Release(&b_ok);
    return result;
}

static PyMethodDef methods[] = {
    {"time_of_day", time_of_day, METH_VARARGS, "Read hhmmss[.sss] fields (see bulk_fields.time_of_day_s)."},
    {"rmc_date", rmc_date, METH_VARARGS, "Read ddmmyy fields (see bulk_fields.rmc_date_days)."},
    {"field_span", field_span, METH_VARARGS, "Field spans of plain lines (see BlockLines.field_span)."},
    {"frame", frame, METH_VARARGS, "Frame the lines of a block (see bulk_lines.split_block)."},
    {"decimal", decimal, METH_VARARGS, "Read decimal fields (see bulk_fields.decimal)."},
    {"gsa_slots", gsa_slots, METH_VARARGS, "Read the satellite slots of GSA lines (see bulk_sentences.gsa)."},
    {"gsv_groups", gsv_groups, METH_VARARGS, "Read the satellite groups of GSV lines (see bulk_sentences.gsv)."},
    {"gsv_reports", gsv_reports, METH_VARARGS, "The GSV report kept per satellite and epoch (see bulk_epochs._gsv_reports)."},
    {"field_decimal", field_decimal, METH_VARARGS, "Read field k of lines as decimals (see BlockLines.field_decimals)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_bulk_kernels",
                                    "Compiled twins of the bulk NMEA reader's kernels.", -1,
                                    methods};

PyMODINIT_FUNC PyInit__bulk_kernels(void) {
    fill_comma_at();
    return PyModule_Create(&module);
}

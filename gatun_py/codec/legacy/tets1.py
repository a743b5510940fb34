"""Tet coding 1 (formats 1 to 4), frozen: the tet stream of the connectivity sections.

The candidates on the current face's edges are ranked by score (faces of T the tet would close)
and then by age; the index is coded in a context of how many candidates there are and the scores
of the best two. An escape's vertex-adjacent list (case c) is in age order. Everything else (the
border, the candidate gather, the escape's kinds, the attachment of a tet) is the shared machinery
of :mod:`gatun_py.codec._cutborder_kernels`, and so is the boundary stream.

:func:`encode_tets` is kept for the tests only (round trips over random meshes check this
decoder beyond the golden files); no file of today is written with it. Its loop keeps its own
opening (scratch, models, the first face) beside today's coder's: a helper shared with today's
coder would let a change there move this frozen coding.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import rangecoder as rc
from .._cutborder_kernels import (EDGE_AB, EDGE_AC, EDGE_BC, ESC, KIND_VERTEX_ADJACENT, MAX_C1, ST_DONE,
                                  ST_ERROR, _apply_tet_inlined, _attach_tet_inlined, _dec_escape, _dec_index,
                                  _emit_tet, _enc_attach, _enc_end, _enc_known_vertex, _enc_new_vertex, _enc_next,
                                  _end_run, _face, _gather_face, _gather_face_inlined, _gather_vertex_adjacent, _kind_context,
                                  _next_face, _remove, _score_context, _sort_candidates, _tet_flip, candidate_lists)

# model layout of the tet stream
N_C1_CTX = 5 * 4 * 4 * 2
TM_C1 = 0
TM_KIND = TM_C1 + N_C1_CTX * 16
TM_C2 = TM_KIND + 8 * 4
TM_FLIP = TM_C2 + 2 * rc.INT_MODEL_SIZE
TM_SIZE = TM_FLIP + 4


def encode_tets(st, out, tets, nbr, tgt, B, dec_of, order, pred, nv0, out_tets, syms):
    """Coding 1 of the tets (for the tests): the arguments of
    :func:`gatun_py.codec._cutborder_kernels.encode_tets` without its ranking state; ``syms``
    holds each tet's candidate index in score order. Returns (vertices, status)."""
    return _encode_tets_run(st, out, tets, nbr, tgt, B, dec_of, order, pred, int(nv0), out_tets, syms,
                            candidate_lists())


@njit(cache=True, nogil=True)
def _encode_tets_run(st, out, tets, nbr, tgt, B, dec_of, order, pred, nv0, out_tets, syms, scratch):
    """The loop of :func:`encode_tets`, with its candidate lists in ``scratch``."""
    cand, cscore, cseq, _, _, c2, c2seq, seen, cface, cface_full = scratch  # cface: unused, _apply_tet walks
    probs = np.full(TM_SIZE, rc.PROB_INIT, np.uint16)
    tvisited = np.zeros(tets.shape[0], np.bool_)
    nv, prev_esc, prev_flip = nv0, 0, 0
    for done in range(tets.shape[0]):
        err, s, t, do, d, a, b, c, behind = _enc_next(B, tets, tgt, tvisited, order, dec_of)
        if err:
            return nv, err
        n1 = _gather_face(B, s, cand, cscore, cseq, cface, cface_full)
        _sort_candidates(cand, cscore, cseq, n1)
        _remove(B, np.int64(3), s)
        ctx = _score_context(n1, cscore, prev_esc, 3)
        sym = ESC
        if d != -1:
            lim = n1 if n1 < MAX_C1 else MAX_C1
            for i in range(lim):
                if cand[i] == d:
                    sym = i
                    break
        # orientation: (a, c, b, d) unless the mesh is folded here (zero-volume tets)
        flip = _tet_flip(tets, t, order[a], order[b], order[c], do)
        rc.enc_sym(st, out, probs, TM_C1 + ctx * 16, 4, sym)
        syms[done] = sym
        if sym != ESC:
            prev_esc = 0
        elif d == -1:
            _enc_new_vertex(st, out, probs, TM_KIND + _kind_context(n1, prev_esc), dec_of, order, pred, nv, do,
                            a, b, c, behind)
            d = nv
            nv += 1
            prev_esc = 1
        else:
            n2 = _gather_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq, seen)
            _enc_known_vertex(st, out, probs, TM_KIND + _kind_context(n1, prev_esc), TM_C2, c2, n2, d, nv, syms,
                              done)
            prev_esc = 1
        err = _enc_attach(st, out, probs, TM_FLIP, prev_flip, flip, out_tets, done, a, b, c, d, B, tets, nbr, tgt,
                          order, t)
        if err:
            return nv, err
        prev_flip = flip
    return nv, _enc_end(st, out, B)


def decode_tets(st, data, probs, m, n_limit, B, pred, tstate, out_tets):
    """Resumable inverse of :func:`encode_tets`, as
    :func:`gatun_py.codec._cutborder_kernels.decode_tets` without its ranking state."""
    return _decode_tets_run(st, data, probs, int(m), int(n_limit), B, pred, tstate, out_tets, candidate_lists())


@njit(cache=True, nogil=True, _nrt=False)
def _decode_tets_run(st, data, probs, m, n_limit, B, pred, tstate, out_tets, scratch):
    """The loop of :func:`decode_tets`, with its candidate lists in ``scratch``."""
    cand, cscore, cseq, cfirst, _, c2, c2seq, seen, cface, cface_full = scratch  # cfirst: the gather order
    nv, done, prev_esc, prev_flip, pred_base = tstate[0], tstate[1], tstate[2], tstate[3], tstate[4]
    limit = min(n_limit, pred_base + pred.shape[0])
    if pred_base > nv:
        return 0, ST_ERROR
    n_out = 0
    status = ST_DONE
    while done < m:
        s, stop = _next_face(st, n_out, out_tets, B)
        if stop >= 0:
            status = stop
            break
        a, b, c, behind = _face(B[0], s)
        cface_full[0] = 0
        n1 = _gather_face_inlined(B, s, cand, cscore, cseq, cface, cface_full)
        for i in range(n1):
            cfirst[i] = cand[i]
        _sort_candidates(cand, cscore, cseq, n1)
        _remove(B, np.int64(3), s)
        ctx = _score_context(n1, cscore, prev_esc, 3)
        sym = rc.dec_sym(st, data, probs, TM_C1 + ctx * 16, np.int64(4))
        if sym < ESC:
            d = cand[sym] if sym < n1 else -1
            prev_esc = 0
        else:
            kind, d, nv = _dec_escape(st, data, probs, TM_KIND, n1, prev_esc, pred, pred_base, nv, limit,
                                      a, b, c, behind)
            if kind == KIND_VERTEX_ADJACENT:
                n2 = _gather_vertex_adjacent(B, a, b, c, cand, n1, c2, c2seq, seen)
                j = _dec_index(st, data, probs, TM_C2, n2)
                d = c2[j] if j >= 0 else -1
            prev_esc = 1
        if d < 0 or d == a or d == b or d == c:
            status = ST_ERROR
            break
        prev_flip = rc.dec_bit(st, data, probs, TM_FLIP + prev_flip)
        t1, t2 = _emit_tet(out_tets, n_out, a, b, c, d, prev_flip)
        n_out += 1
        done += 1
        # the faces this tet closes were noted by the gather (d a candidate), or there are none
        # (d no candidate, the list not full); else they are found on d's list
        i = 0
        while i < n1 and cfirst[i] != d:
            i += 1
        if i < n1:  # faces opposite a, t1, t2: on edges (t1, t2) = (b, c), (a, t2) and (a, t1)
            _attach_tet_inlined(B, a, t1, t2, d, cface[i, EDGE_BC], cface[i, EDGE_AC if prev_flip else EDGE_AB],
                                cface[i, EDGE_AB if prev_flip else EDGE_AC])
        elif cface_full[0] == 0:
            _attach_tet_inlined(B, a, t1, t2, d, -1, -1, -1)
        else:
            _apply_tet_inlined(B, a, t1, t2, d)
    status = _end_run(st, status, B, tstate, nv, done, prev_esc, prev_flip)
    return n_out, status

"""Okapi BM25 lexical ranking, used by ``llm.memory`` when no embedding model is configured.

Small and dependency-free apart from numpy: texts are split into lower-case
alphanumeric words (so ``green_apple`` is ``green`` + ``apple``) and scored with

    score(q, d) = Σ_{t ∈ q} idf(t) · f(t, d) · (k1 + 1) / (f(t, d) + k1 · (1 − b + b · |d| / avgdl))
    idf(t)      = ln(1 + (N − n(t) + 0.5) / (n(t) + 0.5))

where f(t, d) is how often word t occurs in document d, |d| the document's
length in words, avgdl the mean length, N the number of documents and n(t)
how many contain t. idf is always positive, so a document scores 0 exactly
when it shares no word with the query.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Sequence

import numpy as np

__all__ = ["tokenize", "bm25_scores"]

_WORD = re.compile(r"[a-z0-9]+")


def tokenize(text: str) -> list[str]:
    """Lower-case alphanumeric words of ``text``, in order (underscores and punctuation split words)."""
    return _WORD.findall(text.lower())


def bm25_scores(query: str, documents: Sequence[str], k1: float = 1.5, b: float = 0.75) -> np.ndarray:
    """BM25 score of every document for ``query``: float array of shape ``(len(documents),)``.

    ``k1`` (≥ 0) controls how quickly repeated words saturate, ``b`` (0–1) how
    much long documents are penalised. Repeated query words count once.
    """
    if k1 < 0 or not 0.0 <= b <= 1.0:
        raise ValueError(f"need k1 >= 0 and 0 <= b <= 1, got k1={k1}, b={b}")
    scores = np.zeros(len(documents))
    query_terms = set(tokenize(query))
    if not documents or not query_terms:
        return scores
    counts = [Counter(tokenize(doc)) for doc in documents]
    lengths = np.array([sum(c.values()) for c in counts], dtype=float)
    mean_length = lengths.mean() if lengths.mean() > 0 else 1.0
    n_docs = len(documents)
    norm = k1 * (1.0 - b + b * lengths / mean_length)
    for term in query_terms:
        freq = np.array([c.get(term, 0) for c in counts], dtype=float)
        containing = int(np.count_nonzero(freq))
        if containing == 0:
            continue
        idf = math.log(1.0 + (n_docs - containing + 0.5) / (containing + 0.5))
        saturation = np.divide(freq * (k1 + 1.0), freq + norm, out=np.zeros_like(freq), where=freq > 0)
        scores += idf * saturation
    return scores

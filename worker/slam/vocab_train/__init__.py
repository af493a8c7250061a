"""Offline training of the ORB vocabulary tree (`vtdslam train-vocab`); never imported by the runtime path.

`kmajority.py` clusters binary descriptors in Hamming space; `tree.py` builds the k-ary tree from them and the
words' idf; `train.py` reads training images, extracts descriptors with the runtime's own ORB extractor and
writes the vocabulary file that `worker.slam.features.vocabulary.Vocabulary` loads.
"""

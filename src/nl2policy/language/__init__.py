"""From text to trees: text processing, the corpus, augmentation, translators, evaluation."""

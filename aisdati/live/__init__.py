"""`aisdati watch`: a live AIS feed judged as it arrives. Sentences come from a source
(`sources`), are decoded and checked as ingest does (`decode`), kept per vessel in bounded
windows (`vessels`), judged by the model-free event kinds of `aisdati.events` (`judge`), turned
into events opened, extended and closed (`ledger`), stored (`store`), printed and served on a
live page (`serve`); `loop` drives them."""

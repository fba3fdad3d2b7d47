"""The reference study (Anastasio, Fasana, Garibaldi and Marchesiello, EURODYN 2020) reproduced on the
virtual rig: ``negstiff reproduce`` (``reproduce``) and its sections. Only the command line imports this
package; the library never does.
"""

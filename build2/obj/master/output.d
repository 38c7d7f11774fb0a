build2/obj/master/output.o: master/output.c master/output.h \
 common/image/imgio.h common/base/log.h
master/output.h:
common/image/imgio.h:
common/base/log.h:

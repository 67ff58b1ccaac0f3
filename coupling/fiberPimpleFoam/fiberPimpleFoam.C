/*---------------------------------------------------------------------------*\
    fiberform - simulator of early paper forming
    SPDX-License-Identifier: GPL-3.0-or-later
-------------------------------------------------------------------------------
Application
    fiberPimpleFoam

Description
    Transient incompressible solver (PIMPLE) for the suspending fluid of a
    fiber suspension: pimpleFoam on a static mesh plus one explicit momentum
    source, the field fiberSource, which carries the forces of the fibers on
    the fluid in two-way coupling.

        ddt(U) + div(phi U) - div(R) = -grad(p) + fiberSource + fvOptions(U)
        div(U) = 0

    Kinematic units as in every incompressible OpenFOAM solver:
        U           velocity                                [m/s]
        p           pressure / rho                          [m2/s2]
        fiberSource force per unit volume / rho             [m/s2]

    0/fiberSource is optional: when absent the source is zero and the solver
    reproduces pimpleFoam exactly. See docs/coupling/fiberPimpleFoam.md.

Restrictions
    Static mesh (no dynamicMeshDict motion), no MRF zones.

\*---------------------------------------------------------------------------*/

#include "fvCFD.H"
#include "singlePhaseTransportModel.H"
#include "turbulentTransportModel.H"
#include "pimpleControl.H"
#include "fvOptions.H"

// * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * //

int main(int argc, char *argv[])
{
    argList::addNote
    (
        "Transient incompressible PIMPLE solver with a fiber momentum source"
        " (fiberSource, m/s^2) for fiber-fluid coupling."
    );

    #include "postProcess.H"

    #include "addCheckCaseOptions.H"
    #include "setRootCaseLists.H"
    #include "createTime.H"
    #include "createMesh.H"
    #include "createControl.H"
    #include "createTimeControls.H"
    #include "initContinuityErrs.H"
    #include "createFields.H"
    #include "CourantNo.H"
    #include "setInitialDeltaT.H"

    turbulence->validate();

    Info<< "\nStarting time loop\n" << endl;

    while (runTime.run())
    {
        #include "readTimeControls.H"
        #include "CourantNo.H"
        #include "setDeltaT.H"

        ++runTime;

        Info<< "Time = " << runTime.timeName() << nl << endl;

        // Outer (PIMPLE) loop: momentum predictor, then pressure corrections
        while (pimple.loop())
        {
            #include "UEqn.H"

            while (pimple.correct())
            {
                #include "pEqn.H"
            }

            if (pimple.turbCorr())
            {
                laminarTransport.correct();
                turbulence->correct();
            }
        }

        runTime.write();

        runTime.printExecutionTime(Info);
    }

    Info<< "End\n" << endl;

    return 0;
}


// ************************************************************************* //
